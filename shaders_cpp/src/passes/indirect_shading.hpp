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
    std::vector<vec3> radiance;  // incoming radiance along each pixel's secondary ray
    std::vector<float> hitT;     // its hit distance (0 on a miss)
};

// Traces `rays` (one per pixel, inactive ones skipped) with ray type
// `rayType`, shades every hit with emission + one light sample (shadow ray
// type kRayShadow), and adds to `result` (radiance, hitT). `bounce` keys the
// random numbers.
void traceAndShadeSecondary(RenderContext& ctx, const std::vector<SecondaryRay>& rays, RayType rayType,
                            std::uint32_t sample, std::uint32_t bounce, SecondaryResult& result,
                            tracer::TraceCounters& counters);

}  // namespace rtlab::shaders::detail
