// SvgfParams::convergeStatic (issue 16, item 2) on synthetic frames: the long
// mean grows without a cap on a static view, a change of the signal on a
// static pixel restarts it (no ghost), pixels that move are filtered
// exactly as without it, the a-trous reach falls only once the mean has
// more than 8 samples (staticReachExponent), and the shrink toward a short,
// heavy-tailed mean does not take a pixel's own noise whole
// (staticShrinkOwnSigma2).
#include "denoise/denoise_test_util.hpp"

#include <rtlab/denoise/svgf.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

using namespace rtlab;
using namespace rtlab::denoise;
using namespace rtlab::denoise::testing;

namespace {

SvgfParams staticParams() {
    SvgfParams p;
    p.convergeStatic = true;
    return p;
}

// The static tests' signal on a 48 x 32 view: a ramp with a 6-pixel checker
// (which the spatial filter biases).
constexpr int kRampW = 48, kRampH = 32;
double ramp(int x, int y) { return 0.2 + 0.6 * double(x) / kRampW + 0.1 * ((x / 6 + y / 6) % 2); }

// Frame f of the ramp under noise: the ramp + 0.8 x uniform noise, or
// (sparse) 10x the ramp for one sample in ten and 0 otherwise (mean = the
// ramp; heavy-tailed as 1-spp GI is).
std::vector<vec3> rampFrame(std::uint32_t f, bool sparse = false) {
    std::vector<vec3> in(std::size_t(kRampW) * kRampH);
    for (std::size_t i = 0; i < in.size(); ++i) {
        const float t = float(ramp(int(i % kRampW), int(i / kRampW)));
        in[i] = vec3(sparse ? (uniformNoise(i, f) < -0.4f ? 10.f * t : 0.f) : t + 0.8f * uniformNoise(i, f));
    }
    return in;
}

// Mean squared error of the red channel against the ramp.
double rampMse(std::span<const vec3> img) {
    double s = 0.0;
    for (std::size_t i = 0; i < img.size(); ++i) {
        const double d = double(img[i].r) - ramp(int(i % kRampW), int(i / kRampW));
        s += d * d;
    }
    return s / double(img.size());
}

}  // namespace

TEST(DenoiseStaticConvergence, LongMeanGrowsWithoutCapAndTheErrorKeepsFalling) {
    // A ramp (which the spatial filter biases) under uniform noise, static view.
    const GuideBuffers g = flatGuides(kRampW, kRampH);
    SvgfFilter filter(staticParams());
    std::vector<vec3> out(g.pixelCount());
    double at8 = 0, at64 = 0;
    for (std::uint32_t f = 0; f < 64; ++f) {
        filter.filter(g, rampFrame(f), out);
        if (f + 1 == 8) at8 = rampMse(out);
        if (f + 1 == 64) at64 = rampMse(out);
    }
    for (float len : filter.staticLength()) EXPECT_EQ(len, 64.f);  // no cap of 32, no alpha floor
    EXPECT_EQ(filter.staticResets(), 0u);
    ASSERT_TRUE(allFinite(out));
    // The error keeps falling, and after 64 frames it is below that of the
    // plain mean of the 64 samples (noise variance 0.8^2 / 12 / 64).
    EXPECT_GT(at8, 0.0);
    EXPECT_LE(at64, 0.5 * at8) << "after 8 frames " << at8 << ", after 64 " << at64;
    EXPECT_LE(at64, 0.64 / 12.0 / 64.0) << "after 64 frames " << at64;
    // The paper's SVGF plateaus on the same frames.
    SvgfFilter paper;
    for (std::uint32_t f = 0; f < 64; ++f) paper.filter(g, rampFrame(f), out);
    EXPECT_GT(rampMse(out), at64);
}

TEST(DenoiseStaticConvergence, AChangeOnAStaticPixelRestartsTheLongMean) {
    // Static view; at frame 40 the signal steps from 0.2 to 0.8 everywhere (a
    // light switched on). The change test restarts the long mean within a few
    // frames. Measured: output mean 0.27 after 5 frames, restarts in frames
    // 6-8 (0.43 after 8), 0.62 after 16. It lags: a restart takes the fast
    // history, which on a static pixel follows the filtered long mean (the
    // feedback tap); a fast history of its own followed the step sooner
    // (0.64 one frame after the restart) but raised the showcase errors
    // after 64 frames (shadows 64/8 0.233 -> 0.275, GI 0.232 -> 0.324).
    const int w = 24, h = 16;
    const GuideBuffers g = flatGuides(w, h);
    SvgfFilter filter(staticParams());
    std::vector<vec3> out(g.pixelCount());
    std::size_t resets = 0;
    for (std::uint32_t f = 0; f < 56; ++f) {
        const std::vector<vec3> in = noisyGrey(g.pixelCount(), f < 40 ? 0.2f : 0.8f, 0.2f, f);
        filter.filter(g, in, out);
        if (f >= 40 && f < 48) resets += filter.staticResets();
    }
    EXPECT_GE(resets, g.pixelCount() / 2);  // most pixels restart within 8 frames
    double mean = 0.0;
    for (const vec3& c : out) mean += c.r;
    mean /= double(out.size());
    // Without the restart the long mean after 16 frames would be (40 * 0.2 + 16 * 0.8) / 56 = 0.37.
    EXPECT_GT(mean, 0.55);
    EXPECT_LT(mean, 0.85);
}

TEST(DenoiseStaticConvergence, MovingPixelsAreFilteredAsWithout) {
    GuideBuffers g = flatGuides(20, 12);
    g.motion.assign(g.pixelCount(), vec2(0.3f, -0.2f));  // a moving view: 4-tap gathers
    SvgfFilter with(staticParams()), without;
    std::vector<vec3> a(g.pixelCount()), b(g.pixelCount());
    for (std::uint32_t f = 0; f < 12; ++f) {
        const std::vector<vec3> in = noisyGrey(g.pixelCount(), 0.5f, 0.4f, f);
        with.filter(g, in, a);
        without.filter(g, in, b);
        for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i], b[i]) << "frame " << f << " pixel " << i;
    }
    for (float len : with.staticLength()) EXPECT_EQ(len, 0.f);
    // The same with the stacks' static settings (own-rest threshold, shorter
    // reach) and a footprint given to both.
    SvgfParams full = staticParams();
    full.staticShrinkOwnSigma2 = 2.f;
    full.staticReachExponent = 0.5f;
    SvgfFilter withFull(full), withoutFull;
    const std::vector<float> footprint(g.pixelCount(), 6.f);
    for (std::uint32_t f = 0; f < 12; ++f) {
        const std::vector<vec3> in = noisyGrey(g.pixelCount(), 0.5f, 0.4f, f);
        withFull.filter(g, in, a, footprint);
        withoutFull.filter(g, in, b, footprint);
        for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i], b[i]) << "frame " << f << " pixel " << i;
    }
}

TEST(DenoiseStaticConvergence, ReachFallsOnlyOnceTheMeanHasMoreThanEightSamples) {
    // staticReachExponent on the ramp of the first test: up to 8 frames the
    // filter is the same as with the full reach; after 64 the output differs
    // (3 of the 5 iterations) and the error stays close (measured: MSE
    // 0.000613 full, 0.000622 shorter; uniform noise leaves the full reach
    // little bias to lose; its gain is on showcase GI, test_static_view_convergence
    // in tests/shaders_cpp: 0.00203 -> 0.0017 after 64 frames).
    const GuideBuffers g = flatGuides(kRampW, kRampH);
    const auto run = [&](float exponent, std::vector<vec3>& at8, std::vector<vec3>& at64) {
        SvgfParams p = staticParams();
        p.staticReachExponent = exponent;
        SvgfFilter filter(p);
        std::vector<vec3> out(g.pixelCount());
        for (std::uint32_t f = 0; f < 64; ++f) {
            filter.filter(g, rampFrame(f), out);
            if (f + 1 == 8) at8 = out;
        }
        at64 = out;
    };
    std::vector<vec3> full8, full64, shorter8, shorter64;
    run(0.f, full8, full64);
    run(0.5f, shorter8, shorter64);
    EXPECT_EQ(full8, shorter8);
    EXPECT_NE(full64, shorter64);
    ASSERT_TRUE(allFinite(shorter64));
    const double full = rampMse(full64), shorter = rampMse(shorter64);
    std::printf("MSE after 64 frames: full reach %.4g, shorter %.4g\n", full, shorter);
    EXPECT_LT(shorter, 1.05 * full);
}

TEST(DenoiseStaticConvergence, HeavyTailedSamplesAreNotTakenWholeFromAShortMean) {
    // A ramp under sparse, heavy-tailed 1-spp samples (one in ten is 10x the
    // signal, the rest 0: mean = the signal), as 1-spp GI is. After 12 static
    // frames each pixel's long mean is mostly noise. Taking a pixel's own
    // rest whole (staticShrinkOwnSigma2 = 0) wherever its neighbourhood shows
    // a bias puts that noise in the output; with c_own = 2 the output keeps
    // the neighbourhood's smooth correction and has a lower error (measured:
    // MSE 0.0354 with c_own = 0, 0.0170 with c_own = 2).
    const GuideBuffers g = flatGuides(kRampW, kRampH);
    const auto run = [&](float cOwn) {
        SvgfParams p = staticParams();
        p.staticShrinkOwnSigma2 = cOwn;
        SvgfFilter filter(p);
        std::vector<vec3> out(g.pixelCount());
        for (std::uint32_t f = 0; f < 12; ++f) filter.filter(g, rampFrame(f, true), out);
        EXPECT_TRUE(allFinite(out));
        return rampMse(out);
    };
    const double whole = run(0.f), guarded = run(2.f);
    std::printf("MSE after 12 frames: c_own 0 %.4g, c_own 2 %.4g\n", whole, guarded);
    EXPECT_LT(guarded, 0.8 * whole) << "c_own 0: " << whole << ", c_own 2: " << guarded;
}
