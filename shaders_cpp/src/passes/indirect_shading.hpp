#pragma once
// Shading a secondary hit (GI bounce, reflection): its emission plus one
// importance-picked light through a shadow ray (next-event estimation).
// Two dispatches per sample: the secondary rays, then the shadow rays from
// their hits.
#include "../lighting.hpp"

#include <functional>

namespace rtlab::shaders::detail {

struct SecondaryRay {
    bool active = false;
    tracer::RayDesc ray;
};

struct SecondaryResult {
    explicit SecondaryResult(std::size_t n) : radiance(n, vec3(0.f)), hitT(n, 0.f), hits(n, 0) {}
    std::vector<vec3> radiance;       // incoming radiance along each pixel's secondary rays (summed over samples)
    std::vector<float> hitT;          // their hit distances, summed over the rays that hit
    std::vector<std::uint32_t> hits;  // how many hit
    // Mean hit distance over the rays that hit; 0 when none did (the "no hit" value of every hitT layer but AO's).
    float meanHitT(std::size_t i) const { return hits[i] ? hitT[i] / float(hits[i]) : 0.f; }
};

// The 2D grid a batch of secondary rays is dispatched over: the image
// (one ray per pixel) or, for DDGI, rays per probe x probes. Element i is
// (i % width, i / width); random numbers use i as the SampleKey pixel.
struct RayGrid {
    int width = 0, height = 0;
    std::size_t size() const { return std::size_t(width) * std::size_t(height); }
};
RayGrid imageGrid(const RenderContext& ctx);

// Traces `rays` (one per grid element, inactive ones skipped) with ray type
// `rayType`; hits[i] is element i's hit (hit = false when inactive or missed).
void traceSecondary(RenderContext& ctx, const RayGrid& grid, const std::vector<SecondaryRay>& rays, RayType rayType,
                    std::vector<HitPayload>& hits, tracer::TraceCounters& counters);

// An indirect hit's picked area-light sample is combined by MIS with one
// sample of the hit's specular lobe where kLobeMisFromRoughness <= roughness
// < kLobeMisBelowRoughness. Rougher lobes gain little (showcase GI: the same
// errors with every hit included). Lobes below roughness 0.05 (mirrors,
// smooth glass) are left out: their lobe sample would add the caustics of
// lights seen in them (light -> mirror -> the surface that cast the indirect
// ray), rare and bright samples that light points find only near 0.05 and
// practically never at 0 (f is 0 off the mirror direction), so the indirect
// estimators mostly leave those caustics out, as before. With them,
// showcase GI (96x54) after 8 / 64 frames was 0.00361 / 0.00112 instead of
// 0.00318 / 0.000826, the raw 64-frame mean 0.0134 instead of 0.00895.
inline constexpr float kLobeMisFromRoughness = 0.05f;
inline constexpr float kLobeMisBelowRoughness = 0.5f;

// Outgoing radiance toward -incoming[i] at every hit: emission + one light
// picked by importance with its shadow ray (type kRayShadow), at a glossy hit
// (kLobeMisFromRoughness .. kLobeMisBelowRoughness) combined by MIS with one specular-lobe sample per
// hit that counts where it meets an area light (a shadow dispatch per area
// light), times weight[i], added to radiance[i]. `hitStream` (namespace stream) keys the
// random numbers. everyLight: every emitting light instead, no pick noise:
// a point/spot/directional light by one shadow ray; an area light by one
// point on it and one sample of the specular lobe per hit, combined by MIS
// (power heuristic), a shadow ray each (two shadow dispatches per area light).
void shadeHits(RenderContext& ctx, const RayGrid& grid, const std::vector<HitPayload>& hits,
               const std::vector<vec3>& incoming, const std::vector<vec3>& weight, std::uint32_t sample,
               std::uint32_t hitStream, std::vector<vec3>& radiance, tracer::TraceCounters& counters,
               bool everyLight = false);

// traceSecondary + shadeHits, adding radiance and hit distance to `result`.
void traceAndShadeSecondary(RenderContext& ctx, const std::vector<SecondaryRay>& rays, RayType rayType,
                            std::uint32_t sample, std::uint32_t hitStream, SecondaryResult& result,
                            tracer::TraceCounters& counters, bool everyLight = false);

}  // namespace rtlab::shaders::detail
