// The one-light pick of indirect hits (GI, translucency, path tracing,
// DDGI): a picked light's f cos Le / pick pdf must stay bounded, or a rare
// pick becomes a firefly that a static view's history never averages away
// (showcase GI at 160x90: the error doubled at frame 59 from one sample).
#include "../../shaders_cpp/src/lighting.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

namespace rtlab::shaders::detail {
namespace {

ecs::LightSnapshot pointLight(const vec3& position, float intensity) {
    ecs::LightSnapshot l;
    l.light.type = ecs::LightType::Point;
    l.light.intensity = intensity;
    l.worldFromLight[3] = vec4(position, 1.f);
    return l;
}

// A panel at `centre` spanning x, y, emitting along -(x cross y).
ecs::LightSnapshot rectLight(const vec3& centre, const vec3& x, const vec3& y, vec2 size, float intensity) {
    ecs::LightSnapshot l;
    l.light.type = ecs::LightType::Rect;
    l.light.size = size;
    l.light.intensity = intensity;
    l.worldFromLight = mat4(vec4(x, 0.f), vec4(y, 0.f), vec4(glm::normalize(glm::cross(x, y)), 0.f), vec4(centre, 1.f));
    return l;
}

ShadingPoint surface(const vec3& position, const vec3& normal, const vec3& wo, float albedo, float roughness,
                     float metalness) {
    ShadingPoint sp;
    sp.position = position;
    sp.normal = sp.geometricNormal = normal;
    sp.wo = wo;
    sp.albedo = vec3(albedo);
    sp.roughness = roughness;
    sp.metalness = metalness;
    finishShadingPoint(sp);
    return sp;
}

// Each light's pick probability, read back by sweeping u over [0, 1).
std::vector<double> pickFrequencies(const std::vector<ecs::LightSnapshot>& lights, const std::vector<float>& weights,
                                    float share, std::vector<float>& pdfs) {
    const int steps = 200000;
    std::vector<double> counts(lights.size(), 0.0);
    pdfs.assign(lights.size(), -1.f);
    for (int k = 0; k < steps; ++k) {
        float pdf = 0.f;
        const ecs::LightSnapshot* l = pickByWeight(
            lights, [&](const ecs::LightSnapshot& c) { return weights[std::size_t(&c - lights.data())]; },
            (k + 0.5f) / steps, pdf, share);
        const std::size_t i = std::size_t(l - lights.data());
        counts[i] += 1.0 / steps;
        if (pdfs[i] < 0.f) pdfs[i] = pdf;
        EXPECT_EQ(pdfs[i], pdf) << "light " << i << " picked with two pdfs";
    }
    return counts;
}

TEST(LightPick, PdfIsTheFrequencyWithAndWithoutTheUniformShare) {
    const std::vector<ecs::LightSnapshot> lights(4, pointLight(vec3(0.f), 1.f));
    const std::vector<float> weights = {1000.f, 1.f, 0.f, 3.f};
    for (const float share : {0.f, 0.1f, 0.5f}) {
        std::vector<float> pdfs;
        const std::vector<double> freq = pickFrequencies(lights, weights, share, pdfs);
        EXPECT_EQ(freq[2], 0.0) << "a zero weight is never picked";
        for (const std::size_t i : {std::size_t(0), std::size_t(1), std::size_t(3)}) {
            EXPECT_NEAR(freq[i], pdfs[i], 2e-5) << "share " << share << ", light " << i;
            // The uniform part: every light of non-zero weight at least share / 3.
            EXPECT_GE(pdfs[i], share / 3.f * 0.9999f) << "share " << share << ", light " << i;
        }
    }
    // Literal: share 0.1 gives the light of weight 1 0.9 / 1004 + 0.1 / 3.
    std::vector<float> pdfs;
    pickFrequencies(lights, weights, 0.1f, pdfs);
    EXPECT_NEAR(pdfs[1], 0.9 / 1004.0 + 0.1 / 3.0, 1e-7);
    // A single light of non-zero weight is picked with pdf 1 whatever the share.
    float pdf = 0.f;
    const std::vector<float> one = {0.f, 2.f, 0.f, 0.f};
    const ecs::LightSnapshot* l = pickByWeight(
        lights, [&](const ecs::LightSnapshot& c) { return one[std::size_t(&c - lights.data())]; }, 0.01f, pdf, 0.5f);
    EXPECT_EQ(l, &lights[1]);
    EXPECT_EQ(pdf, 1.f);
}

// Seeded: glossy to rough, dielectric and metal surfaces under three white
// point lights, any of them possibly in the mirror direction. The weights
// are irradiance plus pi x the specular response, so a light's f cos Le /
// pdf is at most sum(weights) / pi. With irradiance alone (the weights
// before) a glossy highlight was picked by its cosine only: f cos Le / pdf
// grew with D, without bound as roughness falls.
TEST(LightPick, PointLightsGlossyHighlightIsNotARarePick) {
    std::mt19937 rng(20261125u);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    const vec3 n(0.f, 0.f, 1.f);
    double worstRatio = 0.0;
    int highlights = 0;
    for (int k = 0; k < 2000; ++k) {
        const float roughness = k % 4 == 0 ? 0.05f : 0.05f + 0.95f * u(rng);
        const float theta = 1.5f * u(rng), phi = 6.2831853f * u(rng);
        const vec3 wo(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
        const ShadingPoint sp = surface(vec3(0.f), n, wo, 0.05f + 0.9f * u(rng), roughness, k % 3 == 0 ? 1.f : 0.f);
        std::vector<ecs::LightSnapshot> lights;
        for (int j = 0; j < 3; ++j) {
            vec3 d(2.f * u(rng) - 1.f, 2.f * u(rng) - 1.f, 0.05f + u(rng));
            if (j == 0) d = glm::reflect(-wo, n);  // the highlight
            lights.push_back(pointLight((0.5f + 4.f * u(rng)) * glm::normalize(d), 1.f + 10.f * u(rng)));
        }
        double sum = 0.0;
        for (const auto& l : lights) sum += pointLightImportance(l, sp);
        if (!(sum > 0.0)) continue;
        for (std::size_t j = 0; j < lights.size(); ++j) {
            const float w = pointLightImportance(lights[j], sp);
            const LightSample s = pointLightSample(lights[j], sp.position);
            const float contribution = luminance(evalBrdfCos(sp, s.direction) * s.radianceOverPdf);
            if (!(contribution > 0.f)) continue;
            ASSERT_GT(w, 0.f) << "a light that contributes must be pickable, case " << k;
            const double ratio = contribution / (w / sum) / (sum / kPi);
            worstRatio = std::max(worstRatio, ratio);
            EXPECT_LE(ratio, 1.0 + 1e-4) << "case " << k << ", light " << j << ", roughness " << roughness;
            highlights += j == 0 && roughness == 0.05f && w > 0.5 * sum;
        }
    }
    EXPECT_GT(highlights, 100) << "the glossy highlights must actually dominate some picks";
    EXPECT_GT(worstRatio, 0.5) << "the bound should be nearly tight somewhere";
}

// A ceiling point just behind a one-sided panel hung 1 cm below it (the
// showcase's ceiling light): the panel cannot light it, so it must not take
// the pick from a point light (it took all but 1/1000 of it).
TEST(LightPick, APanelDoesNotTakeThePickFromBehind) {
    ecs::SceneSnapshot scene;
    // Emits along -(x cross -z) = -y: downward.
    scene.lights.push_back(
        rectLight(vec3(0.f, 4.99f, 0.f), vec3(1.f, 0.f, 0.f), vec3(0.f, 0.f, -1.f), vec2(2.f, 1.2f), 12.f));
    scene.lights.push_back(pointLight(vec3(3.f, 3.f, 0.f), 6.f));
    const vec3 down(0.f, -1.f, 0.f);
    const ShadingPoint ceiling =
        surface(vec3(1.5f, 5.f, 0.f), down, glm::normalize(vec3(-1.f, -1.f, 0.f)), 0.7f, 1.f, 0.f);
    float pdf = 0.f;
    const ecs::LightSnapshot* picked = pickLight(scene, ceiling, 0.3f, pdf);
    EXPECT_EQ(picked, &scene.lights[1]);
    EXPECT_EQ(pdf, 1.f);
    EXPECT_EQ(lightPickPdf(scene, ceiling, scene.lights[0]), 0.f);
    // Below the panel's plane the panel is picked by its weight again: u = 0.15
    // lies past the uniform share (0.1), in the weighted part.
    const ShadingPoint wall = surface(vec3(3.9f, 4.f, 0.f), vec3(-1.f, 0.f, 0.f), vec3(-1.f, 0.f, 0.f), 0.7f, 1.f, 0.f);
    ASSERT_LT(kDefensiveLightPickShare, 0.15f);
    picked = pickLight(scene, wall, 0.15f, pdf);
    EXPECT_EQ(picked, &scene.lights[0]);
    const float w0 = lightPickWeight(scene.lights[0], wall), w1 = lightPickWeight(scene.lights[1], wall);
    ASSERT_GT(w0, 0.f);
    ASSERT_GT(w1, 0.f);
    EXPECT_NEAR(pdf, (1.f - kDefensiveLightPickShare) * w0 / (w0 + w1) + kDefensiveLightPickShare / 2.f, 1e-6f);
    // lightPickPdf (the lobe's MIS weight) returns exactly what pickLight reported.
    EXPECT_EQ(lightPickPdf(scene, wall, scene.lights[0]), pdf);
    picked = pickLight(scene, wall, 0.999f, pdf);
    EXPECT_EQ(picked, &scene.lights[1]);
    EXPECT_EQ(lightPickPdf(scene, wall, scene.lights[1]), pdf);
}

// The pick path's MIS (shadeHits without everyLight, at a glossy hit): the
// picked light's sample weighted against one specular-lobe sample, which
// counts each area light it meets with the MIS weight against that light's
// pick pdf x light pdf. The same expectation as the picked sample alone, and
// a far smaller spread on a glossy lobe facing a panel (unshadowed, one
// surface point, a rect panel and a point light; the formulas as in the pass).
TEST(LightPick, LobeMisKeepsThePickedEstimateAndCutsItsTail) {
    ecs::SceneSnapshot scene;
    scene.lights.push_back(rectLight(vec3(0.6f, 0.2f, 2.f), glm::normalize(vec3(1.f, 0.2f, 0.f)),
                                     glm::normalize(vec3(-0.2f, 1.f, 0.f)), vec2(1.5f, 0.8f), 12.f));
    scene.lights.push_back(pointLight(vec3(-1.f, 0.5f, 1.5f), 4.f));
    ASSERT_GT(glm::dot(vec3(scene.lights[0].worldFromLight[2]), vec3(0.f, 0.f, 1.f)), 0.f)
        << "must emit along -z, down";
    for (const float roughness : {0.1f, 0.3f}) {
        const ShadingPoint sp =
            surface(vec3(0.f), vec3(0.f, 0.f, 1.f), glm::normalize(vec3(-0.6f, -0.2f, 2.f)), 0.6f, roughness, 0.3f);
        std::mt19937 rng(11);
        std::uniform_real_distribution<float> u(0.f, 1.f);
        const int n = 400000;
        double sum[2] = {0.0, 0.0}, sum2[2] = {0.0, 0.0};
        for (int k = 0; k < n; ++k) {
            double v[2] = {0.0, 0.0};  // picked sample alone, with the lobe's MIS
            float pickPdf = 0.f;
            const ecs::LightSnapshot* light = pickLight(scene, sp, u(rng), pickPdf);
            const vec2 ul(u(rng), u(rng)), ub(u(rng), u(rng));
            if (light) {
                const bool area = light->light.isArea();
                const LightSample ls =
                    area ? sampleAreaLight(*light, sp.position, ul) : pointLightSample(*light, sp.position);
                if (ls.valid && glm::dot(ls.direction, sp.geometricNormal) > 0.f) {
                    const double f = luminance(evalBrdfCos(sp, ls.direction) * ls.radianceOverPdf) / pickPdf;
                    v[0] = f;
                    v[1] = area ? f * powerHeuristic(1, pickPdf * ls.pdf, 1, specularLobePdf(sp, ls.direction)) : f;
                }
            }
            const BrdfSample b = sampleSpecularLobe(sp, ub);
            if (b.valid)
                for (const ecs::LightSnapshot& l : scene.lights) {
                    if (!l.light.isArea()) continue;
                    const AreaLightHit h = intersectAreaLight(l, sp.position, b.direction);
                    if (!h.valid) continue;
                    const float mis = powerHeuristic(1, b.pdf, 1, lightPickPdf(scene, sp, l) * h.pdf);
                    v[1] += luminance(evalBrdfCos(sp, b.direction) * h.radiance) * mis / b.pdf;
                }
            for (int e = 0; e < 2; ++e) {
                ASSERT_TRUE(std::isfinite(v[e]));
                sum[e] += v[e];
                sum2[e] += v[e] * v[e];
            }
        }
        double mean[2], sd[2];
        for (int e = 0; e < 2; ++e) {
            mean[e] = sum[e] / n;
            sd[e] = std::sqrt(std::max(sum2[e] / n - mean[e] * mean[e], 0.0));
        }
        // Same expectation within 4 standard errors of the difference.
        EXPECT_NEAR(mean[1], mean[0], 4.0 * std::hypot(sd[0], sd[1]) / std::sqrt(double(n)))
            << "roughness " << roughness;
        EXPECT_GT(mean[0], 0.1);
        // The picked sample alone has a heavy tail on the glossy lobe; MIS cuts it
        // (measured, 1e6 samples: sd 24.2 -> 0.57 at roughness 0.1, 2.04 -> 1.06 at 0.3).
        EXPECT_LT(sd[1], (roughness < 0.2f ? 0.1 : 0.7) * sd[0])
            << "roughness " << roughness << ": sd " << sd[0] << " -> " << sd[1];
        std::printf("roughness %.1f: mean %.4f / %.4f, sd per sample %.3f -> %.3f\n", roughness, mean[0], mean[1],
                    sd[0], sd[1]);
    }
}

}  // namespace
}  // namespace rtlab::shaders::detail
