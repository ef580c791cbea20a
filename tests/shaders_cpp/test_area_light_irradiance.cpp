// The closed-form diffuse term of the unshadowed area light (issue 16: a
// cheaper, noise-free unshadowed estimate): literal cases next to seeded
// comparisons with stratified Monte Carlo over the same light sampler.
#include "../../shaders_cpp/src/lighting.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace rtlab::shaders::detail {
namespace {

ecs::LightSnapshot rectLight(const vec3& centre, const vec3& xAxis, const vec3& yAxis, vec2 size) {
    ecs::LightSnapshot l;
    l.light.type = ecs::LightType::Rect;
    l.light.size = size;
    l.light.intensity = 1.f;
    const vec3 z = glm::normalize(glm::cross(xAxis, yAxis));  // emits along -z
    l.worldFromLight = mat4(vec4(xAxis, 0.f), vec4(yAxis, 0.f), vec4(z, 0.f), vec4(centre, 1.f));
    return l;
}

ecs::LightSnapshot sphereLight(const vec3& centre, float radius) {
    ecs::LightSnapshot l;
    l.light.type = ecs::LightType::Sphere;
    l.light.radius = radius;
    l.light.intensity = 1.f;
    l.worldFromLight[3] = vec4(centre, 1.f);
    return l;
}

// The integral of cos over the light's directions above both hemispheres, by
// side x side stratified samples of the renderer's own light sampler.
double sampledCosineIntegral(const ecs::LightSnapshot& l, const vec3& p, const vec3& n, const vec3& ng, int side) {
    double sum = 0.0;
    for (int j = 0; j < side; ++j)
        for (int i = 0; i < side; ++i) {
            const LightSample s = sampleAreaLight(l, p, vec2((i + 0.5f) / side, (j + 0.5f) / side));
            if (!s.valid) continue;
            const float c = glm::dot(n, s.direction);
            if (c > 0.f && glm::dot(ng, s.direction) > 0.f) sum += double(c) * s.radianceOverPdf.x;
        }
    return sum / (double(side) * side);
}

float rectIntegral(const ecs::LightSnapshot& l, const vec3& p, const vec3& n, const vec3& ng) {
    vec3 c[4];
    rectCorners(l, vec3(l.worldFromLight[3]) - p, c);
    return polygonCosineIntegral(c, 4, n, ng);
}

TEST(AreaLightIrradiance, RectLiterals) {
    const vec3 up(0.f, 0.f, 1.f);
    // A square of side 2a at height h straight above: the classic
    // 4 x corner-rectangle form factor, pi F = 4 (a/r) atan(a/r) summed
    // over the two edge directions with r = sqrt(a^2 + h^2) (all over h = 1, a = 1).
    const float a = 1.f, h = 1.f, r = std::sqrt(a * a + h * h);
    const float expected = 4.f * (a / r) * std::atan(a / r);
    const vec3 corners[4] = {{-a, -a, h}, {a, -a, h}, {a, a, h}, {-a, a, h}};
    EXPECT_NEAR(polygonCosineIntegral(corners, 4, up, up), expected, 2e-6f);
    // Winding does not matter.
    const vec3 reversed[4] = {corners[3], corners[2], corners[1], corners[0]};
    EXPECT_NEAR(polygonCosineIntegral(reversed, 4, up, up), expected, 2e-6f);
    // An enormous panel just above covers the hemisphere: pi.
    const vec3 huge[4] = {{-1e6f, -1e6f, 1.f}, {1e6f, -1e6f, 1.f}, {1e6f, 1e6f, 1.f}, {-1e6f, 1e6f, 1.f}};
    EXPECT_NEAR(polygonCosineIntegral(huge, 4, up, up), kPi, 1e-5f);
    // A tiny distant panel: area x cos / d^2 (no cancellation left at small angles).
    const float s = 1e-3f, d = 1e3f;
    const vec3 tiny[4] = {{-s, -s, d}, {s, -s, d}, {s, s, d}, {-s, s, d}};
    EXPECT_NEAR(polygonCosineIntegral(tiny, 4, up, up) / (4.f * s * s / (d * d)), 1.f, 1e-3f);
    // Below the horizon, and cut in half by it (the upper half of a square standing on the horizon).
    const vec3 below[4] = {{-a, 1.f, -2.f}, {a, 1.f, -2.f}, {a, 1.f, -1.f}, {-a, 1.f, -1.f}};
    EXPECT_EQ(polygonCosineIntegral(below, 4, up, up), 0.f);
    const vec3 standing[4] = {{-a, 1.f, -1.f}, {a, 1.f, -1.f}, {a, 1.f, 1.f}, {-a, 1.f, 1.f}};
    const vec3 upperHalf[4] = {{-a, 1.f, 0.f}, {a, 1.f, 0.f}, {a, 1.f, 1.f}, {-a, 1.f, 1.f}};
    EXPECT_NEAR(polygonCosineIntegral(standing, 4, up, up), polygonCosineIntegral(upperHalf, 4, up, up), 1e-6f);
    EXPECT_GT(polygonCosineIntegral(upperHalf, 4, up, up), 0.f);
}

TEST(AreaLightIrradiance, SphereLiterals) {
    const vec3 up(0.f, 0.f, 1.f);
    // Whole cap above: pi sin^2(sigma) cos(theta).
    const float sinSigma = 0.25f;
    const vec3 centre = 4.f * glm::normalize(vec3(1.f, 0.f, 1.f));
    EXPECT_NEAR(*sphereCosineIntegral(centre, 1.f, up, up), kPi * sinSigma * sinSigma * std::sqrt(0.5f), 1e-6f);
    // Centred on the horizon: sigma - sin(sigma) cos(sigma).
    const float sigma = std::asin(sinSigma);
    EXPECT_NEAR(*sphereCosineIntegral(vec3(4.f, 0.f, 0.f), 1.f, up, up), sigma - sinSigma * std::cos(sigma), 1e-6f);
    // Wholly below, and the point inside the light: nothing.
    EXPECT_EQ(*sphereCosineIntegral(vec3(0.f, 0.f, -4.f), 1.f, up, up), 0.f);
    EXPECT_EQ(*sphereCosineIntegral(vec3(0.f, 0.f, 0.5f), 1.f, up, up), 0.f);
    // Cut by the geometric horizon with a different shading normal: no closed form.
    const vec3 tilted = glm::normalize(vec3(0.3f, 0.f, 1.f));
    EXPECT_FALSE(sphereCosineIntegral(vec3(4.f, 0.f, 0.f), 1.f, tilted, up).has_value());
    EXPECT_TRUE(sphereCosineIntegral(vec3(0.f, 0.f, 4.f), 1.f, tilted, up).has_value());
}

// Seeded: random panels and spheres around random surface points (shading
// normal equal to or tilted from the geometric one), closed form against
// 256 x 256 stratified samples.
TEST(AreaLightIrradiance, ClosedFormsMatchStratifiedSampling) {
    std::mt19937 rng(20261125u);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    const auto randomUnit = [&] {
        for (;;) {
            const vec3 v(u(rng), u(rng), u(rng));
            const float l = glm::length(v);
            if (l > 0.1f && l < 1.f) return v / l;
        }
    };
    int rects = 0, spheres = 0, sphereFallbacks = 0;
    for (int k = 0; k < 120; ++k) {
        const vec3 p = 3.f * vec3(u(rng), u(rng), u(rng));
        const vec3 ng = randomUnit();
        const vec3 n = (k % 3 == 0) ? ng : glm::normalize(ng + 0.4f * randomUnit());
        if (!(glm::dot(n, ng) > 0.2f)) continue;
        if (k % 2 == 0) {
            const vec3 x = randomUnit();
            const vec3 y = glm::normalize(glm::cross(x, randomUnit()));
            const ecs::LightSnapshot l = rectLight(p + 2.f * randomUnit(), x, y,
                                                   vec2(0.2f + std::abs(u(rng)) * 2.f, 0.2f + std::abs(u(rng)) * 2.f));
            const vec3 toCentre = vec3(l.worldFromLight[3]) - p;
            const bool front = glm::dot(toCentre, -vec3(l.worldFromLight[2])) < 0.f;
            const float closed = front ? rectIntegral(l, p, n, ng) : 0.f;
            const double sampled = sampledCosineIntegral(l, p, n, ng, 256);
            EXPECT_NEAR(closed, sampled, 2e-3 * std::max(1.0, sampled)) << "rect case " << k;
            ++rects;
        } else {
            const float radius = 0.05f + std::abs(u(rng)) * 0.9f;
            const ecs::LightSnapshot l =
                sphereLight(p + (radius + 0.2f + 2.f * std::abs(u(rng))) * randomUnit(), radius);
            const std::optional<float> closed = sphereCosineIntegral(vec3(l.worldFromLight[3]) - p, radius, n, ng);
            if (!closed) {
                ++sphereFallbacks;
                continue;
            }
            const double sampled = sampledCosineIntegral(l, p, n, ng, 256);
            EXPECT_NEAR(*closed, sampled, 2e-3 * std::max(1.0, sampled)) << "sphere case " << k;
            ++spheres;
        }
    }
    EXPECT_GT(rects, 40);
    EXPECT_GT(spheres, 25);
    EXPECT_GT(sphereFallbacks, 0);
}

// The unshadowed estimate as the shadow pass calls it: its expectation over
// the pixel jitter equals the fully sampled BRDF's (the closed-form diffuse
// plus the sampled specular), finite where the sampler is degenerate.
TEST(AreaLightIrradiance, UnshadowedEstimateKeepsItsExpectation) {
    ShadingPoint sp;
    sp.position = vec3(0.3f, -0.2f, 0.f);
    sp.normal = glm::normalize(vec3(0.1f, 0.f, 1.f));
    sp.geometricNormal = vec3(0.f, 0.f, 1.f);
    sp.wo = glm::normalize(vec3(-0.5f, 0.2f, 1.f));
    sp.albedo = vec3(0.6f, 0.5f, 0.4f);
    sp.roughness = 0.4f;
    finishShadingPoint(sp);
    const ecs::LightSnapshot lights[2] = {
        rectLight(vec3(0.f, 0.f, 2.f), vec3(1.f, 0.f, 0.f), vec3(0.f, 1.f, 0.f), vec2(1.5f, 0.8f)),
        sphereLight(vec3(1.f, 0.5f, 1.5f), 0.4f)};
    // A glossy metal too: there the sampled specular lobe is all of it.
    ShadingPoint metal = sp;
    metal.metalness = 1.f;
    metal.roughness = 0.25f;
    finishShadingPoint(metal);
    for (const ShadingPoint& surface : {sp, metal}) {
        for (const ecs::LightSnapshot& l : lights) {
            // Reference: the whole BRDF by 512 x 512 stratified samples.
            vec3 reference(0.f);
            const int side = 512;
            for (int j = 0; j < side; ++j)
                for (int i = 0; i < side; ++i) {
                    const LightSample s =
                        sampleAreaLight(l, surface.position, vec2((i + 0.5f) / side, (j + 0.5f) / side));
                    if (s.valid) reference += evalBrdfCos(surface, s.direction) * s.radianceOverPdf;
                }
            reference /= float(side * side);
            // The estimate averaged over 256 pixel keys.
            vec3 mean(0.f);
            for (std::uint32_t pixel = 0; pixel < 256; ++pixel) {
                const vec3 e = unshadowedAreaLight(l, surface, 16, SampleKey{pixel, 0, 0, 0, 7}, 2);
                ASSERT_TRUE(std::isfinite(e.x) && std::isfinite(e.y) && std::isfinite(e.z));
                mean += e / 256.f;
            }
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], reference[c], 0.02f * reference[c] + 1e-5f);
            EXPECT_GT(luminance(reference), 0.f);
        }
    }
    // Degenerate: the point on the panel's plane, inside the sphere, a far tiny panel.
    ShadingPoint on = sp;
    on.position = vec3(0.f, 0.f, 2.f);
    finishShadingPoint(on);
    EXPECT_EQ(unshadowedAreaLight(lights[0], on, 16, SampleKey{}, 2), vec3(0.f));
    ShadingPoint inside = sp;
    inside.position = vec3(1.f, 0.5f, 1.5f);
    finishShadingPoint(inside);
    EXPECT_EQ(unshadowedAreaLight(lights[1], inside, 16, SampleKey{}, 2), vec3(0.f));
    const ecs::LightSnapshot far =
        rectLight(vec3(0.f, 0.f, 1e5f), vec3(1.f, 0.f, 0.f), vec3(0.f, 1.f, 0.f), vec2(1e-2f, 1e-2f));
    const vec3 e = unshadowedAreaLight(far, sp, 16, SampleKey{}, 2);
    EXPECT_TRUE(std::isfinite(e.x) && e.x > 0.f);
}

}  // namespace
}  // namespace rtlab::shaders::detail
