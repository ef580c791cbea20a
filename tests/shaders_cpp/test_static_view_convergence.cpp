// Static views converge (issue 16, item 2): with history on a static camera
// every stack keeps lowering its error. On builtin:showcase at 96 x 54, 1 spp
// per frame through `--denoise auto`'s stacks (shadows, reflections, AO, GI),
// relMSE against one shared many-sample reference after 64 frames is at
// most a quarter of its value after 8 frames, and after 12 frames no
// effect shows a field of speckle (isolated outliers). Measured (relMSE
// after 8 / 64 frames): shadows 0.000247 / 5.94e-5, reflections 3.1e-4 /
// 4.3e-5, AO 0.00501 / 0.0011, GI 0.00338 / 0.000833 (docs/denoise.md has
// the history of these figures); before SvgfParams::convergeStatic
// 0.00288 / 0.00306, 3.5e-4 / 3.5e-4, 0.0146 / 0.0151, 0.0065 / 0.0061
// (reflections: with the reflected hit's light sampled without MIS, whose
// rare huge samples left 7.3e-5 / 4.1e-4 with convergeStatic).
#include "shaders_cpp/static_view.hpp"
#include <rtlab/core/image.hpp>
#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

using namespace rtlab;
using namespace rtlab::shaders;

namespace {

Image rgbImage(int w, int h, const std::vector<vec3>& rgb) {
    Image image(w, h);
    image.addRgbLayer("", rgb);
    return image;
}

// Speckle: the fraction of pixels (borders aside) whose luminance is above
// 1.25x the brightest of their 8 neighbours or below 0.8x the darkest.
double isolatedOutliers(int w, int h, const std::vector<vec3>& c) {
    std::size_t count = 0;
    for (int y = 1; y + 1 < h; ++y)
        for (int x = 1; x + 1 < w; ++x) {
            const float l = denoise::luminance(c[std::size_t(y) * w + x]);
            float lo = 1e30f, hi = 0.f;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    if (!dx && !dy) continue;
                    const float q = denoise::luminance(c[std::size_t(y + dy) * w + x + dx]);
                    lo = std::min(lo, q);
                    hi = std::max(hi, q);
                }
            count += l > 1.25f * hi + 1e-4f || l < 0.8f * lo - 1e-4f;
        }
    return double(count) / double((w - 2) * (h - 2));
}

}  // namespace

TEST(StaticConvergence, ShowcaseStacksKeepConvergingWithHistory) {
    const test::StaticView view("builtin:showcase");
    const ecs::SceneSnapshot& scene = view.scene;
    const tracer::AccelManager& accel = view.accel;
    RenderSettings s;
    s.width = 96;
    s.height = 54;
    PlanOptions o;
    o.requested = {Pass::Shadows, Pass::Reflections, Pass::AmbientOcclusion, Pass::GlobalIllumination};
    const FramePlan plan = planFrame(scene, o);
    const std::vector<std::string> effects = {"shadows", "reflections", "ao", "gi"};
    for (Pass p : o.requested) ASSERT_TRUE(plan.has(p));
    const std::size_t n = static_cast<std::size_t>(s.width) * s.height;

    // The reference, shared by the four effects: kRefFrames frames of kRefSpp
    // samples with their own seed (the unshadowed area-light estimate takes a
    // fixed number of samples per frame, so the reference spans many frames).
    // GI, whose 1-spp samples are heavy-tailed, gets kGiRefFrames (a GI-only
    // plan beyond kRefFrames): with 32 its own error (~8e-4) was a third of
    // the 64-frame GI errors measured then (0.0022-0.0031).
    constexpr int kRefFrames = 32, kGiRefFrames = 128, kRefSpp = 64;
    const std::size_t giIndex = 3;
    PlanOptions giOnly;
    giOnly.requested = {Pass::GlobalIllumination};
    const FramePlan giPlan = planFrame(scene, giOnly);
    std::vector<std::vector<glm::dvec3>> sum(effects.size(), std::vector<glm::dvec3>(n, glm::dvec3(0.0)));
    s.spp = kRefSpp;
    s.seed = 0x9e3779b9u;
    for (int f = 0; f < kGiRefFrames; ++f) {
        s.frame = static_cast<std::uint32_t>(f);
        const FrameOutput out = renderFrame(accel, scene, f < kRefFrames ? plan : giPlan, s);
        for (std::size_t e = f < kRefFrames ? 0 : giIndex; e < effects.size(); ++e) {
            const std::vector<vec3> c = effectContribution(out.image, effects[e]);
            for (std::size_t p = 0; p < n; ++p) sum[e][p] += glm::dvec3(c[p]);
        }
    }
    std::vector<Image> reference;
    for (std::size_t e = 0; e < effects.size(); ++e) {
        const double frames = e == giIndex ? kGiRefFrames : kRefFrames;
        std::vector<vec3> ref(n);
        for (std::size_t p = 0; p < n; ++p) ref[p] = vec3(sum[e][p] / frames);
        reference.push_back(rgbImage(s.width, s.height, ref));
    }

    // 64 frames at 1 spp with history, every effect through its stack.
    s.spp = 1;
    s.seed = 0;
    FrameHistory history;
    denoise::EffectLayerDenoiser denoiser(effects);
    std::vector<std::vector<double>> relMse(effects.size()), rawRelMse(effects.size());
    std::vector<double> outliers12(effects.size(), 0.0);
    std::vector<std::vector<glm::dvec3>> rawSum(effects.size(), std::vector<glm::dvec3>(n, glm::dvec3(0.0)));
    for (std::uint32_t f = 0; f < 64; ++f) {
        s.frame = f;
        FrameOutput out = renderFrame(accel, scene, plan, s, history);
        for (std::size_t e = 0; e < effects.size(); ++e) {
            const std::vector<vec3> c = effectContribution(out.image, effects[e]);
            for (std::size_t p = 0; p < n; ++p) rawSum[e][p] += glm::dvec3(c[p]);
        }
        denoiser.apply(out.image);
        if (f + 1 == 12)
            for (std::size_t e = 0; e < effects.size(); ++e)
                outliers12[e] = isolatedOutliers(s.width, s.height, effectContribution(out.image, effects[e]));
        if (f + 1 != 8 && f + 1 != 16 && f + 1 != 32 && f + 1 != 64) continue;
        for (std::size_t e = 0; e < effects.size(); ++e) {
            std::vector<vec3> mean(n);
            for (std::size_t p = 0; p < n; ++p) mean[p] = vec3(rawSum[e][p] / double(f + 1));
            rawRelMse[e].push_back(compareImages(rgbImage(s.width, s.height, mean), reference[e]).relMse);
            const std::vector<vec3> c = effectContribution(out.image, effects[e]);
            for (const vec3& v : c) ASSERT_TRUE(isFinite(v));
            relMse[e].push_back(compareImages(rgbImage(s.width, s.height, c), reference[e]).relMse);
        }
    }
    for (std::size_t e = 0; e < effects.size(); ++e) {
        std::printf("%-12s relMSE after 8 / 16 / 32 / 64 frames: %.3g %.3g %.3g %.3g (64/8 = %.3f)\n",
                    effects[e].c_str(), relMse[e][0], relMse[e][1], relMse[e][2], relMse[e][3],
                    relMse[e][3] / relMse[e][0]);
        std::printf("%-12s (raw accumulation:                   %.3g %.3g %.3g %.3g)\n", effects[e].c_str(),
                    rawRelMse[e][0], rawRelMse[e][1], rawRelMse[e][2], rawRelMse[e][3]);
        EXPECT_TRUE(std::isfinite(relMse[e][0]) && std::isfinite(relMse[e][3]));
        EXPECT_GT(relMse[e][0], 0.0) << effects[e];
        EXPECT_LE(relMse[e][3], 0.25 * relMse[e][0]) << effects[e];
        // No speckle field while the long means are short: after 12 frames at
        // most 4x the reference's isolated outliers + 0.1 % (5 pixels). Loose:
        // it catches the one-step shrink's 1.78 % on GI, not a few pixels more.
        const double referenceOutliers = isolatedOutliers(s.width, s.height, reference[e].rgbLayer(""));
        std::printf("%-12s isolated outliers after 12 frames: %.2f %% (reference %.2f %%)\n", effects[e].c_str(),
                    100.0 * outliers12[e], 100.0 * referenceOutliers);
        EXPECT_LE(outliers12[e], 4.0 * referenceOutliers + 0.001) << effects[e];
    }
}
