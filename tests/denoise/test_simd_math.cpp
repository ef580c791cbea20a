// The denoiser's SIMD math (denoise/src/simd.hpp) against the C library, and
// the a-trous footprint limit.
#include "../../denoise/src/simd.hpp"
#include "denoise/denoise_test_util.hpp"

#include <rtlab/denoise/atrous.hpp>
#include <rtlab/denoise/variance.hpp>

#include <tuple>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using namespace rtlab;
using namespace rtlab::denoise;
using namespace rtlab::denoise::testing;
namespace dsimd = rtlab::denoise::simd;

TEST(DenoiseSimdMath, ExpNegMatchesStdExp) {
    for (float e = 0.f; e < 90.f; e += 0.01f) {
        const dsimd::vfloat<4> v = dsimd::expNeg<4>(dsimd::splat<4>(e));
        const float want = std::exp(-e);
        if (e >= 87.f) {
            EXPECT_EQ(v[0], 0.f) << e;
            continue;
        }
        if (want < 1e-37f) continue;  // denormal range: only finiteness matters
        // e * log2(e) is rounded to a float: relative error ~ 6e-8 * e.
        EXPECT_NEAR(v[0] / want, 1.f, 2e-7f * (1.f + e)) << e;
    }
}

// exp(-e) of -3 (negative counts as 0), NaN, +inf, 3e38 and 0: 1, 0, 0, 0, 1.
template <class ExpNeg>
::testing::AssertionResult specialValuesAreRight(ExpNeg expNeg) {
    const float inf = std::numeric_limits<float>::infinity();
    const dsimd::vfloat<4> v = expNeg(dsimd::vfloat<4>{-3.f, std::nanf(""), inf, 3e38f});
    const float zero = expNeg(dsimd::splat<4>(0.f))[0];
    if (v[0] == 1.f && v[1] == 0.f && v[2] == 0.f && v[3] == 0.f && zero == 1.f) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << "exp(-e) of -3, NaN, inf, 3e38, 0: " << v[0] << ", " << v[1] << ", " << v[2]
                                         << ", " << v[3] << ", " << zero << " (want 1, 0, 0, 0, 1)";
}

TEST(DenoiseSimdMath, ExpNegOfSpecialValues) {
    EXPECT_TRUE(specialValuesAreRight([](const dsimd::vfloat<4>& e) { return dsimd::expNeg<4>(e); }));
}

// The edge-stopping exp (degree-4 polynomial): within its stated 6e-5 of
// std::exp, and defined for any input (a huge term, e.g. a depth difference
// over a zero denominator, gives 0 without an out-of-range conversion:
// UBSan caught one in the spatial variance).
TEST(DenoiseSimdMath, ExpNegWeightMatchesStdExpAndHandlesAnyInput) {
    for (float e = 0.f; e < 87.f; e += 0.01f) {
        const float want = std::exp(-e);
        if (want < 1e-37f) continue;
        EXPECT_NEAR(dsimd::expNegWeight<4>(dsimd::splat<4>(e))[0] / want, 1.f, 6e-5f + 2e-7f * e) << e;
    }
    EXPECT_TRUE(specialValuesAreRight([](const dsimd::vfloat<4>& e) { return dsimd::expNegWeight<4>(e); }));
    EXPECT_EQ(dsimd::expNegWeight<4>(dsimd::splat<4>(87.f))[0], 0.f);
}

TEST(DenoiseSimdMath, Log2MatchesStdLog2) {
    for (float x = 1e-30f; x < 1e30f; x *= 1.37f) {
        const dsimd::vfloat<4> v = dsimd::log2Positive<4>(dsimd::splat<4>(x));
        EXPECT_NEAR(v[0], std::log2(x), 2e-6f * std::fmax(1.f, std::fabs(std::log2(x)))) << x;
    }
}

TEST(DenoiseSimdMath, LanesAreIndependent) {
    // The same value gives the same result in every lane position.
    const dsimd::vfloat<4> a = dsimd::expNeg<4>(dsimd::vfloat<4>{0.3f, 1.7f, 5.5f, 12.f});
    const dsimd::vfloat<4> b = dsimd::expNeg<4>(dsimd::vfloat<4>{12.f, 0.3f, 1.7f, 5.5f});
    EXPECT_EQ(a[0], b[1]);
    EXPECT_EQ(a[1], b[2]);
    EXPECT_EQ(a[2], b[3]);
    EXPECT_EQ(a[3], b[0]);
}

TEST(DenoiseAtrousFootprint, BelowTwoPixelsLeavesThePixelUnfiltered) {
    const int w = 24, h = 16;
    const GuideBuffers g = flatGuides(w, h);
    const std::vector<vec3> noisy = noisyGrey(g.pixelCount(), 1.f, 1.f, 7);
    const std::vector<float> var(g.pixelCount(), 1.f / 12.f);
    std::vector<vec3> out(g.pixelCount());
    std::vector<float> varOut(g.pixelCount());
    atrousFilter(g, noisy, var, {}, out, varOut, 0, {}, std::vector<float>(g.pixelCount(), 1.9f));
    EXPECT_EQ(out, noisy);
}

TEST(DenoiseAtrousFootprint, FootprintSelectsTheNumberOfIterations) {
    // Footprint 4..7 = the steps 1 and 2 only: the same as a 2-iteration filter.
    const int w = 40, h = 32;
    const GuideBuffers g = flatGuides(w, h);
    const std::vector<vec3> noisy = noisyGrey(g.pixelCount(), 1.f, 1.f, 9);
    const std::vector<float> var(g.pixelCount(), 1.f / 12.f);
    std::vector<vec3> limited(g.pixelCount()), two(g.pixelCount());
    std::vector<float> varOut(g.pixelCount());
    atrousFilter(g, noisy, var, {}, limited, varOut, 0, {}, std::vector<float>(g.pixelCount(), 7.f));
    AtrousParams p;
    p.iterations = 2;
    atrousFilter(g, noisy, var, p, two, varOut);
    EXPECT_EQ(limited, two);
    // An unlimited footprint filters more (lower spread around the mean 1).
    std::vector<vec3> full(g.pixelCount());
    atrousFilter(g, noisy, var, {}, full, varOut);
    double spreadTwo = 0, spreadFull = 0;
    for (std::size_t i = 0; i < full.size(); ++i) {
        spreadTwo += (two[i].r - 1.0) * (two[i].r - 1.0);
        spreadFull += (full[i].r - 1.0) * (full[i].r - 1.0);
    }
    EXPECT_LT(spreadFull, 0.5 * spreadTwo);
}

TEST(DenoiseSimdMath, FourAndEightWideFiltersAreBitIdentical) {
    // The SSE2 and the AVX2 paths of the a-trous filter and the spatial
    // variance give the same bits.
    if (!dsimd::hasAvx2()) GTEST_SKIP() << "this CPU has no AVX2: only the 4-wide path exists";
    const int w = 37, h = 23;  // rows that are not a multiple of either width
    GuideBuffers g = flatGuides(w, h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            g.depth[y * w + x] = 1.f + 0.03f * x + (x > 20 ? 0.5f : 0.f);
            g.normal[y * w + x] = glm::normalize(vec3(0.1f * (y % 3), 0.f, 1.f));
            if (x + y < 4) g.meshId[y * w + x] = -1;
        }
    const std::vector<vec3> noisy = noisyGrey(g.pixelCount(), 1.f, 1.f, 11);
    const std::vector<float> var(g.pixelCount(), 0.2f);
    std::vector<float> footprint(g.pixelCount());
    for (std::size_t i = 0; i < footprint.size(); ++i) footprint[i] = float(i % 40);
    const auto run = [&](int width) {
        dsimd::overrideWidth(width);
        std::vector<vec3> out(g.pixelCount());
        std::vector<float> varOut(g.pixelCount());
        atrousFilter(g, noisy, var, {}, out, varOut, 0, {}, footprint);
        // Steps 32 and 64 (beyond the planes' margins: the range-checked path), sigmaN 8 (sky gated by
        // the geometry flag, not by the normal term).
        AtrousParams wide;
        wide.iterations = 7;
        wide.sigmaN = 8.f;
        std::vector<vec3> outWide(g.pixelCount());
        atrousFilter(g, noisy, var, wide, outWide, varOut, 0, {}, {});
        out.insert(out.end(), outWide.begin(), outWide.end());
        HistoryBuffers acc;
        acc.resize(w, h);
        for (std::size_t i = 0; i < acc.moments.size(); ++i) {
            acc.moments[i] = luminanceMoments(noisy[i]);
            acc.length[i] = 1.f;
        }
        std::vector<float> spatial(g.pixelCount());
        estimateVariance(g, acc, {}, spatial);
        dsimd::overrideWidth(0);
        return std::make_tuple(out, varOut, spatial);
    };
    const auto four = run(4), eight = run(8);
    EXPECT_EQ(std::get<0>(four), std::get<0>(eight));
    EXPECT_EQ(std::get<1>(four), std::get<1>(eight));
    EXPECT_EQ(std::get<2>(four), std::get<2>(eight));
}
