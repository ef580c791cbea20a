// sampleScreenStratified2D: the Morton-ordered, Owen-scrambled Sobol'
// (0, 2)-sequence that stratifies a pass's first 2D sample over the screen
// and within each pixel.
#include <rtlab/core/rng.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <vector>

using namespace rtlab;

namespace {

struct Point {
    double u, v;
};

// Every elementary interval [i 2^-a, (i + 1) 2^-a) x [j 2^-b, (j + 1) 2^-b)
// with a + b = log2(points.size()) holds exactly one point: a (0, m, 2)-net.
::testing::AssertionResult isZeroNet(const std::vector<Point>& points) {
    int m = 0;
    while ((std::size_t{1} << m) < points.size()) ++m;
    if ((std::size_t{1} << m) != points.size()) return ::testing::AssertionFailure() << "not a power of two";
    for (int a = 0; a <= m; ++a) {
        const int b = m - a;
        std::set<long> cells;
        for (const Point& p : points) {
            if (!(p.u >= 0.0 && p.u < 1.0 && p.v >= 0.0 && p.v < 1.0))
                return ::testing::AssertionFailure() << "point outside [0, 1)^2: " << p.u << ", " << p.v;
            const long i = static_cast<long>(std::floor(p.u * static_cast<double>(1L << a)));
            const long j = static_cast<long>(std::floor(p.v * static_cast<double>(1L << b)));
            if (!cells.insert(i * (1L << b) + j).second)
                return ::testing::AssertionFailure() << "two points in one 2^-" << a << " x 2^-" << b << " cell";
        }
    }
    return ::testing::AssertionSuccess();
}

SampleKey keyOf(std::uint32_t frame, std::uint32_t seed = 5, std::uint32_t bounce = 3) {
    return SampleKey{0, frame, 0, bounce, seed};
}

Point at(std::uint32_t x, std::uint32_t y, std::uint32_t s, std::uint32_t spp, const SampleKey& k) {
    const vec2 u = sampleScreenStratified2D(x, y, s, spp, k, 0);
    return {u.x, u.y};
}

}  // namespace

TEST(ScreenStratified, LiteralBuildingBlocks) {
    EXPECT_EQ(reverseBits(1u), 0x80000000u);
    EXPECT_EQ(reverseBits(0x0000F00Fu), 0xF00F0000u);
    EXPECT_EQ(mortonIndex(0, 0), 0u);
    EXPECT_EQ(mortonIndex(1, 0), 1u);
    EXPECT_EQ(mortonIndex(0, 1), 2u);
    EXPECT_EQ(mortonIndex(3, 3), 15u);
    EXPECT_EQ(mortonIndex(5, 2), 0b011001u);  // x 101, y 010 -> y2 x2 y1 x1 y0 x0 = 0 1 1 0 0 1
    // Sobol' points 0..3: (0, 0), (1/2, 1/2), (1/4, 3/4), (3/4, 1/4).
    const std::uint32_t expected[4][2] = {
        {0u, 0u}, {0x80000000u, 0x80000000u}, {0x40000000u, 0xC0000000u}, {0xC0000000u, 0x40000000u}};
    for (std::uint32_t i = 0; i < 4; ++i) {
        std::uint32_t a = 1, b = 1;
        sobol2(i, a, b);
        EXPECT_EQ(a, expected[i][0]) << i;
        EXPECT_EQ(b, expected[i][1]) << i;
    }
    // The byte tables against the definition, bit by bit, on seeded random indices.
    for (std::uint32_t n = 0; n < 1000; ++n) {
        const std::uint32_t index = pcgHash(n * 2654435761u);
        std::uint32_t direct = 0;
        std::uint32_t v = 0x80000000u;
        for (int k = 0; k < 32; ++k, v ^= v >> 1)
            if (index & (1u << k)) direct ^= v;
        std::uint32_t a = 0, b = 0;
        sobol2(index, a, b);
        ASSERT_EQ(b, direct) << index;
        ASSERT_EQ(a, reverseBits(index));
    }
    // An Owen scramble is a bijection that keeps aligned blocks: the 16
    // values sharing their top 28 bits map to 16 values sharing theirs.
    std::set<std::uint32_t> images, tops;
    for (std::uint32_t v = 0xABCDE0u; v < 0xABCDE0u + 16u; ++v) {
        const std::uint32_t s = owenScramble(v, 0x1234567u);
        images.insert(s);
        tops.insert(s >> 4);
    }
    EXPECT_EQ(images.size(), 16u);
    EXPECT_EQ(tops.size(), 1u);
}

TEST(ScreenStratified, AnAlignedPixelBlockHoldsANet) {
    // One sample a pixel: the 8 x 8 pixels of an aligned block hold a
    // (0, 6, 2)-net, in any frame; 4 x 4 blocks a (0, 4, 2)-net.
    for (const std::uint32_t frame : {0u, 1u, 17u})
        for (const auto& [bx, by] : {std::pair{0u, 0u}, std::pair{8u, 24u}, std::pair{40u, 16u}}) {
            std::vector<Point> block;
            for (std::uint32_t y = by; y < by + 8; ++y)
                for (std::uint32_t x = bx; x < bx + 8; ++x) block.push_back(at(x, y, 0, 1, keyOf(frame)));
            EXPECT_TRUE(isZeroNet(block)) << "frame " << frame << " block " << bx << ", " << by;
            std::vector<Point> quarter;
            for (std::uint32_t y = by + 4; y < by + 8; ++y)
                for (std::uint32_t x = bx; x < bx + 4; ++x) quarter.push_back(at(x, y, 0, 1, keyOf(frame)));
            EXPECT_TRUE(isZeroNet(quarter)) << "frame " << frame;
        }
    // Control: the same test fails on independent random samples.
    std::vector<Point> random;
    for (std::uint32_t p = 0; p < 64; ++p)
        random.push_back({sampleUniform(SampleKey{p, 0, 0, 0, 1}, 0), sampleUniform(SampleKey{p, 0, 0, 0, 1}, 1)});
    EXPECT_FALSE(isZeroNet(random));
}

TEST(ScreenStratified, APixelsSamplesAreANetAndItsBlocksTogether) {
    // 16 spp: each pixel's 16 samples form a (0, 4, 2)-net, and a 2 x 2 block's 64 a (0, 6, 2)-net.
    const SampleKey k = keyOf(9);
    std::vector<Point> block;
    for (std::uint32_t y = 6; y < 8; ++y)
        for (std::uint32_t x = 10; x < 12; ++x) {
            std::vector<Point> pixel;
            for (std::uint32_t s = 0; s < 16; ++s) pixel.push_back(at(x, y, s, 16, k));
            EXPECT_TRUE(isZeroNet(pixel)) << x << ", " << y;
            block.insert(block.end(), pixel.begin(), pixel.end());
        }
    EXPECT_TRUE(isZeroNet(block));
}

TEST(ScreenStratified, StatelessAndScrambledPerFrameSeedBounceAndDimension) {
    const vec2 a = sampleScreenStratified2D(13, 7, 2, 4, keyOf(3), 0);
    const vec2 b = sampleScreenStratified2D(13, 7, 2, 4, keyOf(3), 0);
    EXPECT_EQ(a, b);
    // The key's pixel and sample fields do not matter (x, y and sample do).
    SampleKey other = keyOf(3);
    other.pixel = 999;
    other.sample = 77;
    const vec2 c = sampleScreenStratified2D(13, 7, 2, 4, other, 0);
    EXPECT_EQ(a, c);
    // Frame, seed, bounce (stream) and dimension each change the scramble.
    for (const vec2 d :
         {sampleScreenStratified2D(13, 7, 2, 4, keyOf(4), 0), sampleScreenStratified2D(13, 7, 2, 4, keyOf(3, 6), 0),
          sampleScreenStratified2D(13, 7, 2, 4, keyOf(3, 5, 4), 0), sampleScreenStratified2D(13, 7, 2, 4, keyOf(3), 3)})
        EXPECT_NE(d, a);
}

TEST(ScreenStratified, IndicesBeyond32BitsTakeAnotherScrambleNotTheSamePoints) {
    // 65536 spp: pixel (256, 0) (Morton index 2^16) has point indices 2^32 +
    // s, the same low 32 bits as pixel (0, 0)'s; its samples must differ.
    EXPECT_EQ(mortonIndex(256, 0), 1u << 16);
    int same = 0;
    for (std::uint32_t s = 0; s < 64; ++s) {
        const Point a = at(0, 0, s, 65536, keyOf(2)), b = at(256, 0, s, 65536, keyOf(2));
        same += a.u == b.u && a.v == b.v;
    }
    EXPECT_EQ(same, 0);
}

TEST(ScreenStratified, UnbiasedOverFramesAndFilteredErrorFarBelowIndependentSamples) {
    // f(u, v) = u v^2 + sin(3u) (integral 1/6 + (1 - cos 3) / 3). Over 400
    // frames, a pixel's 1-spp estimate averages to the integral (seeded
    // property: the scramble makes each point uniform), and the 8 x 8 box
    // filter's estimate varies far less than with independent samples.
    const auto f = [](double u, double v) { return u * v * v + std::sin(3.0 * u); };
    const double integral = 1.0 / 6.0 + (1.0 - std::cos(3.0)) / 3.0;
    constexpr int kFrames = 400;
    double pixelSum = 0.0, boxVarStratified = 0.0, boxVarRandom = 0.0;
    for (std::uint32_t frame = 0; frame < kFrames; ++frame) {
        const Point p = at(21, 5, 0, 1, keyOf(frame));
        pixelSum += f(p.u, p.v);
        double strat = 0.0, rnd = 0.0;
        for (std::uint32_t y = 16; y < 24; ++y)
            for (std::uint32_t x = 32; x < 40; ++x) {
                const Point q = at(x, y, 0, 1, keyOf(frame));
                strat += f(q.u, q.v);
                const SampleKey r{y * 1000 + x, frame, 0, 0, 5};
                rnd += f(sampleUniform(r, 0), sampleUniform(r, 1));
            }
        boxVarStratified += (strat / 64.0 - integral) * (strat / 64.0 - integral);
        boxVarRandom += (rnd / 64.0 - integral) * (rnd / 64.0 - integral);
    }
    // The pixel's mean: the 1-spp variance of f is about 0.1, so 400 frames give a standard error of 0.016.
    EXPECT_NEAR(pixelSum / kFrames, integral, 0.05);
    EXPECT_LT(boxVarStratified, 0.05 * boxVarRandom);
    EXPECT_GT(boxVarRandom, 0.0);
}
