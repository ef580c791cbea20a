#pragma once
// Functional (untimed) closest-hit traversal of one ray through the model's
// two-level BVH (docs/rtcore-model.md, "Traversal"). It produces the hit and
// the per-ray work counts the timing model will charge: node visits, box
// tests, triangle tests, instance transitions and the stack depth.
#include <rtlab/core/math.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>

#include <cstdint>
#include <optional>

namespace rtlab::rtcore_sim {

// A watertight ray/triangle hit: t along the (unnormalised) direction and
// barycentrics b0 + b1 + b2 = 1, weights of p0, p1, p2.
struct TriangleHit {
    float t = 0.f;
    float b0 = 0.f;
    float b1 = 0.f;
    float b2 = 0.f;
};

// Watertight ray/triangle intersection (Woop, Benthin, Wald 2013, as in
// pbrt-v4): shear/permute into ray space, edge functions with a
// double-precision fallback when one is exactly zero, hits with
// 0 < t <= tMax (conservatively > 0), degenerate triangles never hit.
std::optional<TriangleHit> intersectTriangle(const vec3& origin, const vec3& direction, float tMax, const vec3& p0,
                                             const vec3& p1, const vec3& p2);

// The reciprocal direction a slab test uses: 1/d per component, +-inf for a
// zero component (the slab test handles it, see intersectBox).
vec3 reciprocalDirection(const vec3& direction);

// Slab test with conservative rounding (the far distance is scaled by
// 1 + 2 gamma(3), pbrt-v4): the entry distance max(tMin, box entry) when
// the ray's [tMin, tMax] overlaps the box, nothing otherwise. Empty boxes
// (lo > hi) are never hit. For a direction component of zero the slab is the
// whole ray when the origin lies within it (also exactly on a face), no
// part of it otherwise.
std::optional<float> intersectBox(const Aabb& box, const vec3& origin, const vec3& invDirection, float tMin, float tMax);

// A ray with the instance inclusion mask (instance hit when ray.mask &
// instance.mask != 0). Hits are accepted for tMin < t < tMax.
struct ModelRay {
    vec3 origin{0.f};
    float tMin = 0.f;
    vec3 direction{0.f, 0.f, -1.f};
    float tMax = kInfinity;
    std::uint8_t mask = 0xff;
};

struct ModelHit {
    bool hit = false;
    float t = kInfinity;
    std::uint32_t instanceIndex = 0;  // position in ModelScene::instances() (= Embree instID)
    std::uint32_t geometryIndex = 0;  // geometry of the instance's mesh (= Embree geomID)
    std::uint32_t primitiveIndex = 0; // triangle of that geometry (= Embree primID)
    float b0 = 0.f, b1 = 0.f, b2 = 0.f;  // DXR/Embree barycentrics are (u, v) = (b1, b2)
};

// Work one ray did, summed over both levels.
struct TraversalCounters {
    std::uint32_t nodeVisits = 0;           // internal nodes whose child boxes were tested
    std::uint32_t leafVisits = 0;           // leaves processed (TLAS instance leaves and BLAS triangle leaves)
    std::uint32_t boxTests = 0;             // child AABBs tested (= sum of childCount over node visits)
    std::uint32_t triangleTests = 0;        // ray/triangle tests
    std::uint32_t instanceTransitions = 0;  // world->object ray transforms (instances entered after the mask test)
    std::uint32_t maxStackDepth = 0;        // most entries held on the traversal stack at once
};

// Closest hit of `ray` (world space) in `scene`; opaque triangles only.
ModelHit traceClosestHit(const ModelScene& scene, const ModelRay& ray, TraversalCounters& counters);

}  // namespace rtlab::rtcore_sim
