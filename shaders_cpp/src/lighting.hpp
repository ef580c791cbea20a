#pragma once
// Lights and surface response shared by the passes (internal): the BRDF
// (Lambert + GGX/Smith/Schlick), light sampling (rect and sphere area
// lights, point/spot/directional lights picked by importance).
#include "render_context.hpp"

#include <rtlab/shaders_cpp/sampling.hpp>

#include <cmath>
#include <optional>
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
    float transmission = 0.f;  // scales the diffuse lobe by (1 - transmission)
    float errorScale = 0.f;    // for ray offsets (rayOriginLeaving)
    Frame frame;               // shading frame around `normal` (set by finishShadingPoint)
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
// F0 of the specular lobe.
vec3 specularF0(const ShadingPoint& sp);

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
    vec3 direction{0.f};  // unit, from the surface to the light
    float distance = 0.f; // to the sampled point (kInfinity for directional)
    vec3 radianceOverPdf{0.f};  // Le / pdf (solid angle) for area lights, I / d^2 for point lights
    float pdf = 0.f;      // per solid angle for area lights; 0 for point/spot/directional (a delta)
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
// Importance of a point/spot/directional light for a surface: intensity x
// orientation / distance^2, zero out of range or facing away.
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

// One light of `lights` picked with probability weight(light) / sum of
// weights (non-finite or negative weights count as 0); nullptr when every
// weight is 0. `pdf` is the pick probability. Deterministic, any number of
// lights, no allocation (the weights are evaluated twice: sum, then walk).
template <class Weight>
const ecs::LightSnapshot* pickByWeight(const std::vector<ecs::LightSnapshot>& lights, Weight&& weight, float u,
                                       float& pdf) {
    const auto clean = [&](const ecs::LightSnapshot& l) {
        const float w = weight(l);
        return std::isfinite(w) && w > 0.f ? w : 0.f;
    };
    double total = 0.0;
    for (const ecs::LightSnapshot& l : lights) total += clean(l);
    pdf = 0.f;
    if (!(total > 0.0)) return nullptr;
    const double target = double(u) * total;
    double running = 0.0;
    const ecs::LightSnapshot* chosen = nullptr;
    float chosenWeight = 0.f;
    for (const ecs::LightSnapshot& l : lights) {
        const float w = clean(l);
        if (w <= 0.f) continue;
        chosen = &l;  // rounding can leave target at the very end: the last contributing light
        chosenWeight = w;
        running += w;
        if (target < running) break;
    }
    pdf = static_cast<float>(chosenWeight / total);
    return chosen;
}

// One light picked among all lights by importance (area lights weighted by
// intensity x area / distance^2); nullptr when none contributes. `pdf` is
// the pick probability.
const ecs::LightSnapshot* pickLight(const ecs::SceneSnapshot& scene, const ShadingPoint& sp, float u, float& pdf);

}  // namespace rtlab::shaders::detail
