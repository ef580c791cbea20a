#pragma once
// Ray queries without shaders: the closest hit, or whether anything is hit,
// for up to 8 rays on an AccelManager's TLAS, straight from the Embree back
// end. They trace exactly as a pipeline trace of opaque triangles without
// ray flags does (the same object-space rays, the same watertight test, the
// same tie rule; DXR's open interval (tMin, tMax)), so their hits are the
// pipeline's, bit for bit. For benchmarks, replaying recorded rays and tests.
// Procedural primitives are never reported (no intersection shader runs) and
// every geometry counts as opaque. Thread-safe: any number of threads may
// query one AccelManager at once (not while it updates).
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/dxr.hpp>

#include <cstdint>

namespace rtlab::tracer {

struct QueryHit {
    bool hit = false;
    float t = kInfinity;     // ray parameter of the hit (kInfinity on a miss)
    float u = 0.f, v = 0.f;  // barycentric weights of vertices 1 and 2
    std::uint32_t instance = 0, geometry = 0, primitive = 0;
};

// Closest hits of up to 8 rays traced as one packet; lanes with
// active[i] == false are left untouched, invalid rays (isValidRay) miss.
void queryClosest8(const AccelManager& accel, const RayDesc* rays, const bool* active, QueryHit* out,
                   RayCoherence coherence, std::uint32_t instanceMask = 0xff);
// Whether anything lies in (tMin, tMax), for up to 8 rays as one packet.
void queryAny8(const AccelManager& accel, const RayDesc* rays, const bool* active, bool* out, RayCoherence coherence,
               std::uint32_t instanceMask = 0xff);
// One ray at a time.
QueryHit queryClosest(const AccelManager& accel, const RayDesc& ray, std::uint32_t instanceMask = 0xff);
bool queryAny(const AccelManager& accel, const RayDesc& ray, std::uint32_t instanceMask = 0xff);

}  // namespace rtlab::tracer
