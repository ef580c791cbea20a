// Per-effect stacks: the footprint rules (known answers) and the layer
// denoiser's choice of stack.
#include "denoise/denoise_test_util.hpp"

#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/denoise/footprint.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <utility>

using namespace rtlab;
using namespace rtlab::denoise;

namespace {

std::vector<int> allGeometry(std::size_t n) { return std::vector<int>(n, 0); }

bool allFinite(const std::vector<float>& v) {
    for (const float x : v)
        if (!std::isfinite(x)) return false;
    return true;
}

}  // namespace

TEST(DenoiseFootprint, ShadowPenumbraOverPixelWidth) {
    // A uniform 0.5-unit penumbra seen at 0.05 units per pixel: 10 pixels everywhere.
    const int w = 16, h = 12;
    const std::size_t n = std::size_t(w) * h;
    const std::vector<float> fp =
        shadowFootprint(w, h, std::vector<float>(n, 0.5f), std::vector<float>(n, 0.05f), allGeometry(n));
    for (const float v : fp) EXPECT_NEAR(v, 10.f, 1e-4f);
}

TEST(DenoiseFootprint, ShadowBlockerSearchFillsPixelsWithoutAnOccluder) {
    // One column saw an occluder (penumbra 20 px); pixels within the search
    // radius inherit it, pixels beyond it stay 0 (lit: nothing to filter).
    const int w = 40, h = 1;
    std::vector<float> penumbra(w, 0.f);
    penumbra[5] = 2.f;
    FootprintParams p;
    p.smoothRadius = 0;
    const std::vector<float> fp = shadowFootprint(w, h, penumbra, std::vector<float>(w, 0.1f), allGeometry(w), p, 8);
    EXPECT_NEAR(fp[5], 20.f, 1e-4f);
    EXPECT_NEAR(fp[13], 20.f, 1e-4f);  // 8 pixels away: inside the search
    EXPECT_EQ(fp[14], 0.f);            // 9 away: outside
    EXPECT_EQ(fp[39], 0.f);
}

TEST(DenoiseFootprint, ClampedToTheRangeAndZeroOnSky) {
    const int w = 4, h = 1;
    std::vector<int> mesh = {0, 0, 0, -1};
    FootprintParams p;
    p.smoothRadius = 0;
    // 1e9 world / 1e-9 pixel: capped; a tiny penumbra: raised to minPx.
    const std::vector<float> fp = shadowFootprint(w, h, std::vector<float>{1e9f, 1e-6f, 0.f, 5.f},
                                                  std::vector<float>{1e-9f, 1.f, 1.f, 1.f}, mesh, p, 0);
    EXPECT_EQ(fp[0], p.maxPx);
    EXPECT_EQ(fp[1], p.minPx);
    EXPECT_EQ(fp[2], 0.f);
    EXPECT_EQ(fp[3], 0.f);  // sky
}

TEST(DenoiseFootprint, ReflectionFromRoughnessAndHitDistance) {
    const int w = 4, h = 1;
    FootprintParams p;
    p.smoothRadius = 0;
    // roughness 0 (mirror): 0; 0.5 at hitT 4 and 0.1 per pixel: 2 * 0.25 * 4 / 0.1 = 20; a miss: maxPx.
    const std::vector<float> fp =
        reflectionFootprint(w, h, std::vector<float>{0.f, 0.5f, 0.5f, 0.1f}, std::vector<float>{3.f, 4.f, 0.f, 1.f},
                            std::vector<float>(4, 0.1f), allGeometry(4), p);
    EXPECT_EQ(fp[0], 0.f);
    EXPECT_NEAR(fp[1], 20.f, 1e-4f);
    EXPECT_EQ(fp[2], p.maxPx);
    EXPECT_EQ(fp[3], p.minPx);  // 2 * 0.01 * 1 / 0.1 = 0.2 -> raised to 2
}

TEST(DenoiseFootprint, ReflectionEdgesOfTheReflectedImageGetOneIteration) {
    // A glossy floor (roughness 0.5, 0.1 units per pixel) whose reflection
    // shows a near box (hit distance 1) left of column 10 and a far wall (8)
    // right of it: lobe footprints 5 and 40 px. Within smoothRadius (2) of
    // the reflected edge the window spans 8x > 4x: capped at 2 px (one
    // iteration); farther away the footprint is the window mean, untouched.
    const int w = 20, h = 6;
    const std::size_t n = std::size_t(w) * h;
    std::vector<float> hitT(n);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) hitT[std::size_t(y) * w + x] = x < 10 ? 1.f : 8.f;
    const std::vector<float> roughness(n, 0.5f), pixelWorld(n, 0.1f);
    FootprintParams p;
    const std::vector<float> plain = reflectionFootprint(w, h, roughness, hitT, pixelWorld, allGeometry(n), p);
    p.edgeHitRatio = 4.f;
    const std::vector<float> edged = reflectionFootprint(w, h, roughness, hitT, pixelWorld, allGeometry(n), p);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::size_t i = std::size_t(y) * w + x;
            const bool nearEdge = x >= 8 && x <= 11;
            EXPECT_EQ(edged[i], nearEdge ? 2.f : plain[i]) << x << "," << y;
            if (nearEdge) {
                EXPECT_GT(plain[i], 2.f) << x;  // the cap does bind there
            }
        }
    EXPECT_NEAR(plain[0], 5.f, 1e-4f);
    EXPECT_NEAR(plain[w - 1], 40.f, 1e-4f);

    // Within the ratio (8x at ratio 10) nothing changes; a miss counts as far
    // (an edge against the sky); another mesh in the window is no edge.
    p.edgeHitRatio = 10.f;
    EXPECT_EQ(reflectionFootprint(w, h, roughness, hitT, pixelWorld, allGeometry(n), p), plain);
    p.edgeHitRatio = 4.f;
    std::vector<float> sky = hitT;
    for (float& t : sky) t = t > 1.f ? 0.f : t;  // the far side: misses
    const std::vector<float> againstSky = reflectionFootprint(w, h, roughness, sky, pixelWorld, allGeometry(n), p);
    EXPECT_EQ(againstSky[9], 2.f);
    std::vector<int> mesh(n, 0);
    for (int y = 0; y < h; ++y)
        for (int x = 10; x < w; ++x) mesh[std::size_t(y) * w + x] = 1;
    const std::vector<float> twoMeshes = reflectionFootprint(w, h, roughness, hitT, pixelWorld, mesh, p);
    p.edgeHitRatio = 0.f;
    EXPECT_EQ(twoMeshes, reflectionFootprint(w, h, roughness, hitT, pixelWorld, mesh, p));
}

TEST(DenoiseFootprint, SurfacePixelWidthIsTheAreaEquivalentWidthOnTheSlope) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    // Facing the camera; 45 degrees (depth changes by a pixel's width per
    // pixel: 1 / cos = sqrt(2)); 80 degrees along y; grazing (capped at
    // 100x); a NaN gradient (as facing); pixel widths 0, -1, +inf, NaN pass through.
    const std::vector<float> pixelWorld = {0.1f, 0.1f, 0.2f, 0.1f, 0.1f, 0.f, -1.f, inf, nan};
    const std::vector<vec2> grad = {vec2(0.f),       vec2(0.06f, 0.08f), vec2(0.f, 0.2f * std::tan(1.3962634f)),
                                    vec2(1e9f, 0.f), vec2(nan, 0.f),     vec2(1.f),
                                    vec2(1.f),       vec2(1.f),          vec2(1.f)};
    const std::vector<float> s = surfacePixelWorld(pixelWorld, grad);
    ASSERT_EQ(s.size(), pixelWorld.size());
    EXPECT_EQ(s[0], 0.1f);
    EXPECT_NEAR(s[1], 0.1f * std::sqrt(std::sqrt(2.f)), 1e-6f);
    EXPECT_NEAR(s[2], 0.2f / std::sqrt(std::cos(1.3962634f)), 1e-4f);
    EXPECT_NEAR(s[3], 0.1f * 100.f, 1e-3f);
    EXPECT_EQ(s[4], 0.1f);
    EXPECT_EQ(s[5], 0.f);
    EXPECT_EQ(s[6], -1.f);
    EXPECT_EQ(s[7], inf);
    EXPECT_TRUE(std::isnan(s[8]));
    EXPECT_THROW(surfacePixelWorld(pixelWorld, std::vector<vec2>(2)), std::invalid_argument);

    // In pixels, an AO footprint on a 60-degree slope is sqrt(cos 60) = 0.71 of the same
    // surface's facing the camera: its pixels are wider on the surface.
    const int w = 8, h = 8;
    const std::size_t n = std::size_t(w) * h;
    const std::vector<float> across(n, 0.05f), occluder(n, 1.f), visibility(n, 0.5f);
    const std::vector<float> slope = surfacePixelWorld(across, std::vector<vec2>(n, vec2(0.f, 0.05f * std::sqrt(3.f))));
    const std::vector<float> facing = aoFootprint(w, h, occluder, visibility, across, allGeometry(n));
    const std::vector<float> tilted = aoFootprint(w, h, occluder, visibility, slope, allGeometry(n));
    EXPECT_NEAR(facing[27], 20.f, 1e-3f);
    EXPECT_NEAR(tilted[27], 20.f * std::sqrt(0.5f), 1e-3f);
}

TEST(DenoiseFootprint, AoFromOccluderDistance) {
    FootprintParams p;
    p.smoothRadius = 0;
    const std::vector<float> fp = aoFootprint(3, 1, std::vector<float>{0.05f, 0.5f, 100.f}, std::vector<float>(3, 0.f),
                                              std::vector<float>(3, 0.1f), allGeometry(3), p);
    EXPECT_EQ(fp[0], p.minPx);  // contact: 0.5 px -> the smallest kernel
    EXPECT_NEAR(fp[1], 5.f, 1e-4f);
    EXPECT_EQ(fp[2], p.maxPx);  // open
}

TEST(DenoiseFootprint, AoUnoccludedPixelsTakeTheirOccludedNeighboursScale) {
    // A contact crease at 1 spp: occluders 0.05 away (0.5 px), one pixel whose
    // ray escaped (visibility 1, hitT = the radius 0.5: 5 px), then the open
    // (nothing hit anywhere in the window: the radius's 5 px).
    FootprintParams p;
    p.smoothRadius = 1;
    const std::vector<float> hitT = {0.05f, 0.5f, 0.05f, 0.5f, 0.5f, 0.5f, 0.5f};
    const std::vector<float> visibility = {0.f, 1.f, 0.f, 1.f, 1.f, 1.f, 1.f};
    const std::vector<float> fp = aoFootprint(7, 1, hitT, visibility, std::vector<float>(7, 0.1f), allGeometry(7), p);
    EXPECT_EQ(fp[1], p.minPx);       // the crease's scale, not the open's
    EXPECT_EQ(fp[3], p.minPx);       // one occluded neighbour in the window
    EXPECT_NEAR(fp[5], 5.f, 1e-5f);  // no occluder within the window: the AO radius
}

TEST(DenoiseFootprint, NonFiniteInputGivesFiniteFootprints) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const std::vector<float> bad = {nan, inf, -inf, -1.f, 0.f, 1e30f};
    const std::vector<int> mesh = allGeometry(bad.size());
    EXPECT_TRUE(allFinite(shadowFootprint(6, 1, bad, bad, mesh)));
    EXPECT_TRUE(allFinite(reflectionFootprint(6, 1, bad, bad, bad, mesh)));
    EXPECT_TRUE(allFinite(aoFootprint(6, 1, bad, bad, bad, mesh)));
    EXPECT_THROW(aoFootprint(5, 1, bad, bad, bad, mesh), std::invalid_argument);
}

namespace {

// A frame with the guide layers (flat, facing the camera) and one shadow
// layer: visibility 1 left, 0 right, a hard edge (penumbra 0 left of the
// edge's occluder, i.e. no occluder seen on the lit side; 0 on the shadowed
// side too: a contact shadow with no penumbra).
Image shadowFrame(int w, int h, float penumbraOnShadowedSide, bool withPixelWorld = true) {
    Image f(w, h);
    f.addChannel("depth.Z", 1.f);
    f.addChannel("id.mesh", 0.f);
    f.addChannel("motion.X", 0.f);
    f.addChannel("motion.Y", 0.f);
    f.addChannel("normal.R", 0.f);
    f.addChannel("normal.G", 0.f);
    f.addChannel("normal.B", 1.f);
    if (withPixelWorld) f.addChannel("footprint.pixelWorld", 0.01f);
    float* v = f.addChannel("shadow.light0.V", 1.f);
    float* pen = f.addChannel("shadow.light0.penumbra", 0.f);
    for (int y = 0; y < h; ++y)
        for (int x = w / 2; x < w; ++x) {
            v[y * w + x] = 0.f;
            pen[y * w + x] = penumbraOnShadowedSide;
        }
    return f;
}

}  // namespace

TEST(DenoiseStacks, ShadowLayersUseTheShadowStackAndOthersSvgf) {
    Image f = shadowFrame(16, 8, 0.f);
    f.addChannel("ao.V", 1.f);
    f.addChannel("ao.hitT", 1.f);
    EffectLayerDenoiser d({"shadows", "ao"});
    const std::vector<DenoisedLayer> layers = d.apply(f);
    ASSERT_EQ(layers.size(), 2u);
    EXPECT_EQ(layers[0].layer, "shadow.light0.V");
    EXPECT_EQ(layers[0].stack, DenoiseStack::Shadow);
    EXPECT_EQ(layers[1].layer, "ao.V");
    EXPECT_EQ(layers[1].stack, DenoiseStack::AmbientOcclusion);
    EXPECT_TRUE(f.hasChannel("noisy.shadow.light0.V"));
    // Without the pixel footprint (an older EXR) every layer falls back to SVGF.
    Image old = shadowFrame(16, 8, 0.f, false);
    EXPECT_EQ(EffectLayerDenoiser({"shadows"}).apply(old)[0].stack, DenoiseStack::Svgf);
}

TEST(DenoiseStacks, ZeroPenumbraLeavesAHardShadowUnfiltered) {
    // No occluder distance anywhere within reach -> footprint 0 -> the noisy
    // (here: exact) visibility passes through bit-exactly.
    Image f = shadowFrame(24, 8, 0.f);
    const std::vector<float> before(f.channel("shadow.light0.V"), f.channel("shadow.light0.V") + f.pixelCount());
    EffectLayerDenoiser({"shadows"}).apply(f);
    for (std::size_t i = 0; i < before.size(); ++i) EXPECT_EQ(f.channel("shadow.light0.V")[i], before[i]) << i;
}

TEST(DenoiseStacks, NoisyPenumbraIsSmoothedAndStaysInRange) {
    // A wide penumbra (1 unit = 100 px) with 1-spp binary visibility noise
    // around 0.5: the stack lowers the spread and keeps values in [0, 1].
    const int w = 48, h = 32;
    Image f = shadowFrame(w, h, 1.f);
    float* v = f.channel("shadow.light0.V");
    float* pen = f.channel("shadow.light0.penumbra");
    double spreadBefore = 0, spreadAfter = 0;
    const std::vector<vec3> noise = rtlab::denoise::testing::noisyGrey(f.pixelCount(), 0.5f, 1.f, 3);
    for (std::size_t i = 0; i < f.pixelCount(); ++i) {
        pen[i] = 1.f;
        v[i] = noise[i].r > 0.5f ? 1.f : 0.f;
        spreadBefore += (v[i] - 0.5) * (v[i] - 0.5);
    }
    EffectLayerDenoiser({"shadows"}).apply(f);
    for (std::size_t i = 0; i < f.pixelCount(); ++i) {
        EXPECT_GE(f.channel("shadow.light0.V")[i], 0.f);
        EXPECT_LE(f.channel("shadow.light0.V")[i], 1.f + 1e-6f);
        spreadAfter += (f.channel("shadow.light0.V")[i] - 0.5) * (f.channel("shadow.light0.V")[i] - 0.5);
    }
    EXPECT_LT(spreadAfter, 0.2 * spreadBefore);
}

namespace {

// A frame with every stack's layers, filled with `value` (and the guides).
Image allStacksFrame(int w, int h, float value) {
    Image f = shadowFrame(w, h, 0.5f);
    for (const char* c : {"shadow.light0.V", "ao.V"}) {
        float* v = f.hasChannel(c) ? f.channel(c) : f.addChannel(c);
        for (std::size_t i = 0; i < f.pixelCount(); ++i) v[i] = value;
    }
    f.addChannel("ao.hitT", 0.5f);
    f.addChannel("roughness.Y", 0.2f);
    f.addChannel("reflection.hitT", 2.f);
    f.addRgbLayer("reflection", std::vector<vec3>(f.pixelCount(), vec3(value)));
    f.addRgbLayer("gi", std::vector<vec3>(f.pixelCount(), vec3(value)));
    f.addRgbLayer("direct.pointPicked", std::vector<vec3>(f.pixelCount(), vec3(value)));
    f.addRgbLayer("albedo", std::vector<vec3>(f.pixelCount(), vec3(0.5f)));
    return f;
}

// Every denoised layer is finite (the noisy.* copies keep the input as it was).
bool layersFinite(const Image& f) {
    for (const std::string& c : f.channelNames()) {
        if (c.rfind("noisy.", 0) == 0) continue;
        for (std::size_t i = 0; i < f.pixelCount(); ++i)
            if (!std::isfinite(f.channel(c)[i])) {
                ADD_FAILURE() << c << "[" << i << "] = " << f.channel(c)[i];
                return false;
            }
    }
    return true;
}

}  // namespace

TEST(DenoiseStacks, ExtremeInputsStayFiniteOnEveryStack) {
    // All black, all white, HDR white, tiny images, a single 1e20 firefly,
    // NaN and Inf in the signal: every stack's output is finite, two frames.
    for (const auto& [w, h] : {std::pair{1, 1}, std::pair{3, 2}, std::pair{17, 9}})
        for (const float value : {0.f, 1.f, 1e4f}) {
            EffectLayerDenoiser d;
            for (int frame = 0; frame < 2; ++frame) {
                Image f = allStacksFrame(w, h, value);
                if (frame == 1 && f.pixelCount() > 1) {
                    f.channel("reflection.R")[0] = 1e20f;
                    f.channel("ao.V")[f.pixelCount() - 1] = std::numeric_limits<float>::quiet_NaN();
                    f.channel("gi.G")[0] = std::numeric_limits<float>::infinity();
                }
                const std::vector<DenoisedLayer> done = d.apply(f);
                EXPECT_EQ(done.size(), 5u);  // shadow V, direct.pointPicked, reflection, ao, gi
                EXPECT_TRUE(layersFinite(f)) << w << "x" << h << " value " << value << " frame " << frame;
            }
        }
}

TEST(DenoiseStacks, ConstantSignalStaysConstant) {
    // Zero variance: every stack returns the constant (remodulation included).
    for (const float value : {0.f, 0.25f, 1.f}) {
        Image f = allStacksFrame(20, 12, value);
        EffectLayerDenoiser().apply(f);
        for (const char* c : {"shadow.light0.V", "ao.V", "reflection.R", "gi.B", "direct.pointPicked.G"})
            for (std::size_t i = 0; i < f.pixelCount(); ++i) EXPECT_NEAR(f.channel(c)[i], value, 1e-6f) << c;
    }
}

TEST(DenoiseStacks, ResultsDoNotDependOnTheThreadCount) {
    const auto run = [](int threads) {
        const ThreadLimit limit(threads);
        Image f = allStacksFrame(45, 31, 0.5f);
        const std::vector<vec3> noise = rtlab::denoise::testing::noisyGrey(f.pixelCount(), 0.5f, 1.f, 5);
        for (std::size_t i = 0; i < f.pixelCount(); ++i) {
            f.channel("shadow.light0.V")[i] = noise[i].r > 0.5f ? 1.f : 0.f;
            f.channel("ao.V")[i] = noise[i].r;
            f.channel("reflection.G")[i] = 4.f * noise[i].r * noise[i].r;
        }
        EffectLayerDenoiser().apply(f);
        return f;
    };
    const Image one = run(1), two = run(2);
    for (const std::string& c : one.channelNames())
        for (std::size_t i = 0; i < one.pixelCount(); ++i)
            ASSERT_EQ(one.channel(c)[i], two.channel(c)[i]) << c << " " << i;
}
