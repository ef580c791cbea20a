#pragma once
// Lights and surface response shared by the passes (internal): the BRDF
// (Lambert + GGX/Smith/Schlick), light sampling (rect and sphere area
// lights, point/spot/directional lights picked by importance).
#include "render_context.hpp"

#include <rtlab/shaders_cpp/sampling.hpp>

#include <algorithm>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

namespace rtlab::shaders::detail {

// The surface a BRDF is evaluated on.
struct ShadingPoint {
    vec3 position{0.f};
    vec3 normal{0.f, 0.f, 1.f};           // shading normal
    vec3 geometricNormal{0.f, 0.f, 1.f};  // on the side of the viewer
    vec3 wo{0.f, 0.f, 1.f};               // toward the viewer (unit)
    vec3 albedo{0.f};
    float roughness = 1.f;
    float metalness = 0.f;
    float transmission = 0.f;     // scales the diffuse lobe by (1 - transmission)
    float errorScale = 0.f;       // for ray offsets (rayOriginLeaving)
    Frame frame;                  // shading frame around `normal` (set by finishShadingPoint)
    vec3 woLocal{0.f, 0.f, 1.f};  // wo in that frame
};
// Sets the cached frame and local wo once the fields above are filled.
void finishShadingPoint(ShadingPoint& sp);
ShadingPoint shadingPointOf(const GPixel& g);
ShadingPoint shadingPointOf(const HitPayload& hit, const ecs::Material& m, const vec3& wo);

// f(wo, wi) * cos(theta_i); 0 below the surface.
vec3 evalBrdfCos(const ShadingPoint& sp, const vec3& wi);
// The diffuse part only: (1 - metalness)(1 - transmission) albedo / pi * cos(theta_i).
vec3 evalDiffuseCos(const ShadingPoint& sp, const vec3& wi);
// The specular (GGX) part only; evalBrdfCos = evalDiffuseCos + evalSpecularCos.
vec3 evalSpecularCos(const ShadingPoint& sp, const vec3& wi);
// F0 of the specular lobe (from the base colour and metalness alone).
vec3 specularF0(const ShadingPoint& sp);
vec3 specularF0(const vec3& albedo, float metalness);

// Sampling the BRDF: the diffuse (cosine) or the GGX (visible normals)
// lobe, picked with probabilities from the lobes' estimated albedos; pdf is
// the mixture pdf of both lobes per solid angle. valid = false when wo is
// below the surface, the BRDF is black, or the direction leaves below the
// geometric normal.
struct BrdfSample {
    vec3 direction{0.f};  // world, unit
    float pdf = 0.f;
    bool valid = false;
};
BrdfSample sampleBrdf(const ShadingPoint& sp, float uLobe, vec2 u);
// Sampling the specular lobe alone (GGX visible normals, whatever the
// diffuse lobe's weight): the strategy that finds a glossy highlight.
BrdfSample sampleSpecularLobe(const ShadingPoint& sp, vec2 u);
// The pdf sampleSpecularLobe has for world direction wi (0 where it cannot sample it).
float specularLobePdf(const ShadingPoint& sp, const vec3& wi);

// A point sampled on a light, seen from a surface point.
struct LightSample {
    vec3 direction{0.f};        // unit, from the surface to the light
    float distance = 0.f;       // to the sampled point (kInfinity for directional)
    vec3 radianceOverPdf{0.f};  // Le / pdf (solid angle) for area lights, I / d^2 for point lights
    float pdf = 0.f;            // per solid angle for area lights; 0 for point/spot/directional (a delta)
    bool valid = false;
};
// The shadow ray from surface point p (geometric normal ng) to the light
// sample: its origin is offset off the surface (rayOriginLeaving), and the
// direction and length are re-aimed from that origin at the sampled point,
// so the offset cannot carry the ray past the light (e.g. through a ceiling
// the light hangs just below).
tracer::RayDesc shadowRayToward(const LightSample& ls, const vec3& p, const vec3& ng, float errorScale);

// Area light (rect or sphere) sample from `p` with two uniforms.
LightSample sampleAreaLight(const ecs::LightSnapshot& light, const vec3& p, vec2 u);
// Where the ray from `p` along unit `direction` meets an area light's
// emitting side: the light's radiance there (Le, the same everywhere),
// the distance and the solid-angle pdf with which sampleAreaLight would pick
// that direction. valid = false (pdf 0) when the ray misses the light, hits
// a rect's back or the light is not an area light. Lights are not geometry:
// nothing but the light itself is tested here (the caller's shadow ray does that).
struct AreaLightHit {
    vec3 radiance{0.f};
    float distance = 0.f;
    float pdf = 0.f;
    bool valid = false;
};
AreaLightHit intersectAreaLight(const ecs::LightSnapshot& light, const vec3& p, const vec3& direction);
// The penumbra width (world units) an area light casts at receiver `p` from
// an occluder `occluderDistance` away toward the light (the PCSS estimate,
// Fernando 2005: light size x occluder distance / occluder-to-light
// distance; light size = the rect's diagonal or the sphere's diameter). 0
// without an occluder (occluderDistance <= 0); capped at 1e6 light sizes.
// The shadow denoiser turns it into its kernel footprint.
float penumbraWidth(const ecs::LightSnapshot& light, const vec3& p, float occluderDistance);
// Point, spot or directional light toward `p` (no sampling needed).
LightSample pointLightSample(const ecs::LightSnapshot& light, const vec3& p);
// Importance of a point/spot/directional light for a surface: its
// irradiance (intensity x cos / distance^2) plus pi x the specular lobe's
// response toward it, so that a glossy highlight is never a rare pick: for a
// white light f cos Le / importance <= 1 / pi for any lobe (coloured light
// on a coloured lobe can exceed it, by at most 1 / the smallest luminance
// weight, 0.0722); zero out of range or facing away.
float pointLightImportance(const ecs::LightSnapshot& light, const ShadingPoint& sp);

// The unshadowed direct light of one area light (the shadow pass's
// "unshadowed" signal, no rays): the diffuse term in closed form
// (polygonCosineIntegral / sphereCosineIntegral), the specular term by
// `samples` stratified samples; the diffuse term is sampled too where no
// closed form applies (a sphere light cut by the geometric horizon of a
// surface whose shading normal differs from it).
vec3 unshadowedAreaLight(const ecs::LightSnapshot& light, const ShadingPoint& sp, int samples, const SampleKey& key,
                         std::uint32_t dimension);
// The integral of cos(theta) = n . w over the directions w toward a convex
// polygon (`count` <= 8 corners relative to the surface point, in order)
// that lie above both planes n . w >= 0 and ng . w >= 0 (Lambert's formula
// after clipping). A Lambertian surface of albedo a under a polygon of
// uniform radiance L receives a / pi x L x this.
float polygonCosineIntegral(const vec3* corners, int count, const vec3& n, const vec3& ng);
// A rect light's four corners in order, relative to a surface point from
// which the light's centre is at `toCentre`.
void rectCorners(const ecs::LightSnapshot& light, const vec3& toCentre, vec3* corners);
// The same for a sphere of `radius` centred at `toCentre` from the surface
// point, clipped to the n hemisphere (Snyder 1996); nothing when the sphere
// also crosses the ng horizon and n != ng (no closed form: sample it).
std::optional<float> sphereCosineIntegral(const vec3& toCentre, float radius, const vec3& n, const vec3& ng);

// Whether a light emits at all (the planner counts the same lights).
bool emits(const ecs::LightSnapshot& light);

// A light's pick weight with non-finite or negative values as 0.
template <class Weight>
float cleanPickWeight(Weight& weight, const ecs::LightSnapshot& l) {
    const float w = weight(l);
    return std::isfinite(w) && w > 0.f ? w : 0.f;
}

// The sum of the weights and how many are non-zero.
template <class Weight>
std::pair<double, std::size_t> pickWeightTotal(const std::vector<ecs::LightSnapshot>& lights, Weight& weight) {
    double total = 0.0;
    std::size_t count = 0;
    for (const ecs::LightSnapshot& l : lights) {
        const float w = cleanPickWeight(weight, l);
        total += w;
        count += w > 0.f;
    }
    return {total, count};
}

// The uniform share actually mixed in: none when one light (or none) has weight.
inline double effectiveUniformShare(float uniformShare, std::size_t count) {
    return count > 1 ? std::clamp(double(uniformShare), 0.0, 1.0) : 0.0;
}

// The pick probability of a light of weight w: (1 - share) w / total + share / count.
inline float mixturePickPdf(float w, double total, std::size_t count, double share) {
    return static_cast<float>((1.0 - share) * (double(w) / total) + share / double(count));
}

// One light of `lights` picked with probability weight(light) / sum of
// weights (non-finite or negative weights count as 0); nullptr when every
// weight is 0. `pdf` is the pick probability. Deterministic, any number of
// lights, no allocation (the weights are evaluated twice: sum, then walk).
// uniformShare > 0 mixes in a uniform pick among the lights of non-zero
// weight (defensive importance sampling, Hesterberg 1995): a light the
// weights underrate is still picked with probability >= uniformShare / count,
// so its f cos Le / pdf stays bounded.
template <class Weight>
const ecs::LightSnapshot* pickByWeight(const std::vector<ecs::LightSnapshot>& lights, Weight&& weight, float u,
                                       float& pdf, float uniformShare = 0.f) {
    const auto [total, count] = pickWeightTotal(lights, weight);
    pdf = 0.f;
    if (!(total > 0.0)) return nullptr;
    // Step: which of the two strategies, and u rescaled to [0, 1) within it.
    const double share = effectiveUniformShare(uniformShare, count);
    const bool uniform = double(u) < share;
    const double v = uniform ? double(u) / share : (double(u) - share) / (1.0 - share);
    const double target = v * (uniform ? double(count) : total);
    double running = 0.0;
    const ecs::LightSnapshot* chosen = nullptr;
    float chosenWeight = 0.f;
    for (const ecs::LightSnapshot& l : lights) {
        const float w = cleanPickWeight(weight, l);
        if (w <= 0.f) continue;
        chosen = &l;  // rounding can leave target at the very end: the last contributing light
        chosenWeight = w;
        running += uniform ? 1.0 : double(w);
        if (target < running) break;
    }
    // Step: the mixture's pdf of the light picked (either strategy could have picked it).
    pdf = mixturePickPdf(chosenWeight, total, count, share);
    return chosen;
}

// The probability with which pickByWeight (same weights and share) picks `light`.
template <class Weight>
float pickPdfByWeight(const std::vector<ecs::LightSnapshot>& lights, Weight&& weight, const ecs::LightSnapshot& light,
                      float uniformShare = 0.f) {
    const auto [total, count] = pickWeightTotal(lights, weight);
    const float w = cleanPickWeight(weight, light);
    if (!(total > 0.0) || !(w > 0.f)) return 0.f;
    return mixturePickPdf(w, total, count, effectiveUniformShare(uniformShare, count));
}

// The importance pickLight gives a light at a surface point: for point,
// spot and directional lights pointLightImportance; for area lights
// intensity x area / distance^2 (an overestimate near their plane), 0 where
// the light is wholly below the surface or the point behind a one-sided panel.
float lightPickWeight(const ecs::LightSnapshot& light, const ShadingPoint& sp);
// The share of pickLight's probability spread evenly over the lights of
// non-zero weight: bounds what a light the weights underrate costs.
inline constexpr float kDefensiveLightPickShare = 0.1f;
// One light picked among all lights by lightPickWeight, mixed with
// kDefensiveLightPickShare of a uniform pick; nullptr when none contributes.
// `pdf` is the pick probability.
const ecs::LightSnapshot* pickLight(const ecs::SceneSnapshot& scene, const ShadingPoint& sp, float u, float& pdf);
// The probability with which pickLight picks `light` at sp (0 if never).
float lightPickPdf(const ecs::SceneSnapshot& scene, const ShadingPoint& sp, const ecs::LightSnapshot& light);

}  // namespace rtlab::shaders::detail
