// core/simd.hpp: the lane-bit masks of comparisons, every pattern, both widths.
#include <rtlab/core/simd.hpp>

#include <gtest/gtest.h>

using namespace rtlab;

TEST(Simd, SignMaskHasOneBitPerTrueLaneForEveryPattern) {
    for (std::uint32_t bits = 0; bits < 256; ++bits) {
        simd::vint<8> m8;
        for (int i = 0; i < 8; ++i) m8[i] = (bits >> i) & 1u ? -1 : 0;
        EXPECT_EQ(simd::signMask<8>(m8), bits);
        if (bits < 16) {
            simd::vint<4> m4;
            for (int i = 0; i < 4; ++i) m4[i] = (bits >> i) & 1u ? -1 : 0;
            EXPECT_EQ(simd::signMask<4>(m4), bits);
        }
    }
    // From a comparison, as the kernels use it.
    const simd::vfloat<8> a{1, -2, 3, -4, 0, -0.f, 5, -6};
    EXPECT_EQ(simd::signMask<8>(a < simd::splat<8>(0.f)), 0b10001010u);
}
