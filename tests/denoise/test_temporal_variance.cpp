// Temporal accumulation (history length, alpha floor, moments) and the
// variance estimate (temporal, and the spatial fallback for short histories).
#include "denoise/denoise_test_util.hpp"

#include <rtlab/denoise/temporal.hpp>
#include <rtlab/denoise/variance.hpp>

#include <gtest/gtest.h>

using namespace rtlab;
using namespace rtlab::denoise;
using namespace rtlab::denoise::testing;

namespace {

// Runs one frame of reproject + accumulate on `state` (empty = first frame).
void step(const GuideBuffers& cur, const GuideBuffers* prev, std::span<const vec3> color, HistoryBuffers& state,
          const TemporalParams& params = {}) {
    HistoryBuffers reprojected;
    if (prev) {
        reprojectHistory(reproject(cur, *prev), state, reprojected);
    } else {
        reprojected.resize(cur.width, cur.height);
    }
    accumulateTemporal(color, reprojected, params, state);
}

}  // namespace

TEST(DenoiseTemporal, StaticHistoryGrowsAndDisocclusionResetsIt) {
    const int w = 8, h = 6;
    const GuideBuffers g = flatGuides(w, h);
    const std::vector<vec3> color = constantImage(g.pixelCount(), 0.5f);
    HistoryBuffers state;
    step(g, nullptr, color, state);
    for (float len : state.length) EXPECT_EQ(len, 1.f);
    for (int f = 2; f <= 6; ++f) {
        step(g, &g, color, state);
        for (float len : state.length) EXPECT_EQ(len, static_cast<float>(f));
    }
    // A new object covers the 3x3 top-left block; the rightmost column moved in
    // from off screen (motion points past the right border).
    GuideBuffers cur = g;
    for (int y = 0; y < 3; ++y)
        for (int x = 0; x < 3; ++x) cur.meshId[y * w + x] = 9;
    for (int y = 0; y < h; ++y) cur.motion[y * w + (w - 1)] = vec2(2.f, 0.f);
    step(cur, &g, color, state);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const bool disoccluded = (x < 3 && y < 3) || x == w - 1;
            EXPECT_EQ(state.length[y * w + x], disoccluded ? 1.f : 7.f) << x << "," << y;
        }
    // And the colour of a disoccluded pixel is the new sample, not a blend.
    EXPECT_EQ(state.color[0], vec3(0.5f));
}

TEST(DenoiseTemporal, HistoryLengthSaturatesAtTheCap) {
    const GuideBuffers g = flatGuides(3, 2);
    const std::vector<vec3> color = constantImage(g.pixelCount(), 1.f);
    HistoryBuffers state;
    TemporalParams p;
    p.maxHistoryLength = 5.f;
    step(g, nullptr, color, state, p);
    for (int f = 0; f < 10; ++f) step(g, &g, color, state, p);
    for (float len : state.length) EXPECT_EQ(len, 5.f);
}

TEST(DenoiseTemporal, AlphaIsMaxOfFloorAndOneOverHistory) {
    // Frames 1, 2, 3, ...: while 1/history > alpha the result is the running
    // mean (1, 1.5, 2, 2.5, 3); from history 6 on the 0.2 floor takes over
    // (3 + 0.2 (6 - 3) = 3.6, not the mean 3.5).
    const GuideBuffers g = flatGuides(4, 4);
    HistoryBuffers state;
    const float expected[6] = {1.f, 1.5f, 2.f, 2.5f, 3.f, 3.6f};
    const float expectedM2[5] = {1.f, 2.5f, 14.f / 3.f, 7.5f, 11.f};  // running mean of k^2
    for (int f = 1; f <= 6; ++f) {
        const std::vector<vec3> color = constantImage(g.pixelCount(), static_cast<float>(f));
        step(g, f == 1 ? nullptr : &g, color, state);
        EXPECT_NEAR(state.color[5].r, expected[f - 1], 1e-6) << "frame " << f;
        EXPECT_NEAR(state.moments[5].x, expected[f - 1], 1e-6) << "frame " << f;
        if (f <= 5) {
            EXPECT_NEAR(state.moments[5].y, expectedM2[f - 1], 1e-5) << "frame " << f;
        }
    }
}

TEST(DenoiseTemporal, MomentsHaveTheirOwnAlpha) {
    const GuideBuffers g = flatGuides(2, 2);
    TemporalParams p;
    p.alpha = 0.5f;
    p.momentsAlpha = 0.2f;
    HistoryBuffers state;
    for (int f = 0; f < 20; ++f) step(g, f == 0 ? nullptr : &g, constantImage(4, 0.f), state, p);
    step(g, &g, constantImage(4, 1.f), state, p);
    EXPECT_NEAR(state.color[0].r, 0.5f, 1e-7);
    EXPECT_NEAR(state.moments[0].x, 0.2f, 1e-7);
    EXPECT_NEAR(state.moments[0].y, 0.2f, 1e-7);
}

TEST(DenoiseTemporal, ConstantInputStaysExactlyConstant) {
    GuideBuffers g = flatGuides(7, 5);
    g.motion.assign(g.pixelCount(), vec2(0.3f, -0.7f));  // fractional motion: 4-tap gathers
    const std::vector<vec3> color = constantImage(g.pixelCount(), 0.731f);
    HistoryBuffers state;
    step(g, nullptr, color, state);
    for (int f = 0; f < 10; ++f) step(g, &g, color, state);
    for (std::size_t i = 0; i < g.pixelCount(); ++i) {
        EXPECT_NEAR(state.color[i].r, 0.731f, 1e-6f);
        EXPECT_NEAR(state.moments[i].x, 0.731f, 1e-6f);
    }
    std::vector<float> var(g.pixelCount());
    estimateVariance(g, state, {}, var);
    for (float v : var) EXPECT_NEAR(v, 0.f, 1e-6f);
}

TEST(DenoiseVariance, TemporalEstimateMatchesTheNoiseVariance) {
    // Uniform noise of amplitude 1: variance 1/12. The moments are exponential
    // moving averages with weight a, whose first moment has variance
    // a/(2-a) sigma^2, so E[m2 - m1^2] = sigma^2 * 2(1-a)/(2-a).
    const int w = 64, h = 64;
    const GuideBuffers g = flatGuides(w, h);
    const double sigma2 = 1.0 / 12.0;
    for (const float a : {0.2f, 0.02f}) {
        TemporalParams p;
        p.momentsAlpha = a;
        HistoryBuffers state;
        const int frames = a > 0.1f ? 60 : 600;
        for (int f = 0; f < frames; ++f)
            step(g, f == 0 ? nullptr : &g, noisyGrey(g.pixelCount(), 1.f, 1.f, static_cast<std::uint32_t>(f)), state,
                 p);
        std::vector<float> var(g.pixelCount());
        estimateVariance(g, state, {}, var);  // history >= 4 everywhere: the temporal estimate
        double mean = 0;
        for (float v : var) mean += v;
        mean /= static_cast<double>(var.size());
        const double expected = sigma2 * 2.0 * (1.0 - a) / (2.0 - a);
        EXPECT_NEAR(mean, expected, 0.03 * expected) << "alpha " << a;
        EXPECT_NEAR(mean, sigma2, (a > 0.1f ? 0.15 : 0.03) * sigma2) << "alpha " << a;
    }
}

TEST(DenoiseVariance, SpatialFallbackWhileHistoryIsShort) {
    // First frame (history 1): the variance comes from the 7x7 neighbourhood of
    // a flat surface, whose weights are all 1: E = sigma^2 * 48/49.
    const int w = 48, h = 48;
    const GuideBuffers g = flatGuides(w, h);
    HistoryBuffers state;
    step(g, nullptr, noisyGrey(g.pixelCount(), 1.f, 1.f, 0), state);
    std::vector<float> var(g.pixelCount());
    estimateVariance(g, state, {}, var);
    double mean = 0;
    int count = 0;
    for (int y = 3; y < h - 3; ++y)
        for (int x = 3; x < w - 3; ++x) {
            mean += var[y * w + x];
            ++count;
        }
    mean /= count;
    const double expected = (1.0 / 12.0) * 48.0 / 49.0;
    EXPECT_NEAR(mean, expected, 0.05 * expected);

    // Falcor's boost multiplies it by 4 / history = 4.
    VarianceParams boost;
    boost.boostShortHistory = true;
    std::vector<float> boosted(g.pixelCount());
    estimateVariance(g, state, boost, boosted);
    EXPECT_NEAR(boosted[20 * w + 20], 4.f * var[20 * w + 20], 1e-6f);

    // With the threshold at 1 the per-pixel temporal estimate (0 for one sample) is used.
    VarianceParams temporalOnly;
    temporalOnly.historyThreshold = 1.f;
    estimateVariance(g, state, temporalOnly, var);
    for (float v : var) EXPECT_EQ(v, 0.f);
}

TEST(DenoiseVariance, SpatialFallbackDoesNotMixAcrossDepthOrNormalEdges) {
    // Noise-free halves 0 | 1: a 7x7 box across the edge would see variance.
    const int w = 16, h = 8;
    for (int kind = 0; kind < 3; ++kind) {  // 0: no edge in the guides (control), 1: depth edge, 2: normal edge
        GuideBuffers g = flatGuides(w, h);
        std::vector<vec3> color(g.pixelCount());
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                const std::size_t i = static_cast<std::size_t>(y) * w + x;
                color[i] = vec3(x < w / 2 ? 0.f : 1.f);
                if (x >= w / 2 && kind == 1) g.depth[i] = 3.f;
                if (x >= w / 2 && kind == 2) g.normal[i] = vec3(1.f, 0.f, 0.f);
            }
        HistoryBuffers state;
        step(g, nullptr, color, state);
        std::vector<float> var(g.pixelCount());
        estimateVariance(g, state, {}, var);
        const float atEdge = var[4 * w + w / 2 - 1];
        if (kind == 0) {
            EXPECT_GT(atEdge, 0.1f);
        } else {
            for (float v : var) EXPECT_LT(v, 1e-6f) << "kind " << kind;
        }
    }
}
