#pragma once
// Watertight ray/triangle intersection (Woop, Benthin, Wald 2013, "Watertight
// Ray/Triangle Intersection", JCGT 2(1)), evaluated in double precision so
// that edge functions shared by two triangles are exact negations and a ray
// through a shared edge or vertex cannot slip between the triangles.
#include <rtlab/core/math.hpp>

#include <optional>

namespace rtlab::tracer {

struct TriangleHit {
    float t = 0.f;
    float b1 = 0.f;  // barycentric weight of p1 (Embree/DXR "u")
    float b2 = 0.f;  // barycentric weight of p2 (Embree/DXR "v")
};

// Hit with tMin < t < tMax, or nothing. Degenerate triangles never hit.
std::optional<TriangleHit> intersectTriangleWatertight(const vec3& origin, const vec3& direction, const vec3& p0,
                                                       const vec3& p1, const vec3& p2, float tMin, float tMax);

}  // namespace rtlab::tracer
