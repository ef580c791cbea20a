#pragma once
// Watertight ray/triangle intersection (Woop, Benthin, Wald 2013, "Watertight
// Ray/Triangle Intersection", JCGT 2(1)) in single precision, as pbrt-v4 does
// it. The ray is translated to the origin, its axes permuted so that z is the
// dominant direction axis and the triangle sheared so the ray runs along +z;
// the three 2D edge functions then decide the hit. A vertex shared by two
// triangles is transformed by the same operations in both, and the same edge
// gives exactly negated edge values (e = qx*py - qy*px in one, px*qy - py*qx
// in the other: the same two products), so a ray through a shared edge or
// vertex cannot slip between the triangles. Zero edge values count as inside
// (both neighbours may report the hit; hit_order.hpp picks one).
//
// Three forms with identical arithmetic, so that they give the same bits:
//   intersectTriangleWatertight   one triangle (the RT-core model's triangle unit)
//   intersectClusterWatertight    up to 4 triangles in structure-of-arrays form,
//                                 one 4-wide SIMD step (Embree's watertight
//                                 user geometry for single rays)
//   intersectPacketWatertight     one triangle against 8 rays per SIMD step
//                                 (Embree's packets)
// Both rely on lane-wise IEEE float arithmetic without FMA contraction (ISO
// mode; core/simd.hpp).
#include <rtlab/core/math.hpp>

#include <array>
#include <cstdint>
#include <optional>

namespace rtlab::tracer {

struct TriangleHit {
    float t = 0.f;
    float b1 = 0.f;  // barycentric weight of p1 (Embree/DXR "u")
    float b2 = 0.f;  // barycentric weight of p2 (Embree/DXR "v")
};

// The per-ray constants of the test: axis permutation, the origin's
// permuted coordinates and the shear.
struct WatertightRay {
    int kx = 0, ky = 1, kz = 2;
    float ox = 0.f, oy = 0.f, oz = 0.f;  // origin[kx], origin[ky], origin[kz]
    float sx = 0.f, sy = 0.f, sz = 0.f;
    bool valid = false;  // false for a zero direction: nothing is hit
};
WatertightRay makeWatertightRay(const vec3& origin, const vec3& direction);

// Hit with tMin < t < tMax, or nothing. Degenerate triangles never hit.
std::optional<TriangleHit> intersectTriangleWatertight(const WatertightRay& ray, const vec3& p0, const vec3& p1,
                                                       const vec3& p2, float tMin, float tMax);
inline std::optional<TriangleHit> intersectTriangleWatertight(const vec3& origin, const vec3& direction, const vec3& p0,
                                                              const vec3& p1, const vec3& p2, float tMin, float tMax) {
    return intersectTriangleWatertight(makeWatertightRay(origin, direction), p0, p1, p2, tMin, tMax);
}

// Up to kClusterTriangles triangles of one geometry, vertex coordinates in
// structure-of-arrays form: v[vertex][axis][slot]. Unused slots hold a
// degenerate triangle (all vertices equal), which never hits. Four slots:
// clusters end where merging stops paying (buildClusters in
// accel_manager.cpp; 1 to 4 triangles), and a 176-byte cluster keeps the
// working set near Embree's own triangle leaves (an 8-slot one took 352
// bytes for the same triangles).
inline constexpr int kClusterTriangles = 4;
struct alignas(16) TriangleCluster {
    std::uint32_t count = 0;  // first: shares a cache line with the vertices
    float v[3][3][kClusterTriangles] = {};
    std::array<std::uint32_t, kClusterTriangles> primitive{};  // triangle index in the geometry per slot

    vec3 vertex(int slot, int k) const { return vec3(v[k][0][slot], v[k][1][slot], v[k][2][slot]); }
    void set(int slot, const vec3& p0, const vec3& p1, const vec3& p2);
};

// The hits of one cluster test: bit s of `mask` says slot s was hit with
// tMin < t < tMax; t/b1/b2 are valid for those slots.
struct ClusterHits {
    std::uint32_t mask = 0;
    alignas(16) float t[kClusterTriangles];
    alignas(16) float b1[kClusterTriangles];
    alignas(16) float b2[kClusterTriangles];
};

// Tests every slot of `cluster` in one 4-wide SIMD step; slot s gives exactly
// intersectTriangleWatertight's result.
void intersectClusterWatertight(const WatertightRay& ray, const TriangleCluster& cluster, float tMin, float tMax,
                                ClusterHits& out);

// Up to 8 rays in structure-of-arrays form (an Embree packet), each lane
// with its own WatertightRay constants and open interval (tMin, tMax).
struct alignas(32) WatertightRayPacket {
    static constexpr int kLanes = 8;
    // Not initialised here (a packet is set up per callback); setRays writes
    // every lane (zeros where a ray is invalid), so inactive lanes never
    // compute with garbage.
    alignas(32) std::int32_t xIs0[kLanes], xIs1[kLanes];  // -1 where kx == 0 / kx == 1 (else kx == 2)
    alignas(32) std::int32_t yIs0[kLanes], yIs1[kLanes];
    alignas(32) std::int32_t zIs0[kLanes], zIs1[kLanes];
    alignas(32) std::int32_t permutation[kLanes];  // a code of (kx, ky, kz), equal for equal permutations
    alignas(32) float ox[kLanes], oy[kLanes], oz[kLanes];
    alignas(32) float sx[kLanes], sy[kLanes], sz[kLanes];
    alignas(32) float tMin[kLanes], tMax[kLanes];
    std::uint32_t validRays = 0;   // lanes whose ray has a non-zero direction
    std::uint32_t activeMask = 0;  // lanes to test: valid rays the caller activated
    // All active lanes share one axis permutation (kx, ky, kz): the vertices
    // are then permuted once per triangle instead of per lane.
    bool uniform = false;
    int kx = 0, ky = 1, kz = 2;
    // All valid lanes share one permutation (found once by setRays): then any
    // activated subset does, with no per-lane check.
    bool uniformValid = false;

    // Every lane from structure-of-arrays origins and directions (8 each):
    // the same constants as makeWatertightRay per lane, 8 lanes per SIMD step.
    void setRays(const float* ox, const float* oy, const float* oz, const float* dx, const float* dy, const float* dz);
    // Lane `lane` as a single ray (valid only where validRays has its bit).
    WatertightRay ray(int lane) const {
        WatertightRay r;
        r.valid = (validRays >> lane) & 1u;
        r.kx = xIs0[lane] ? 0 : xIs1[lane] ? 1 : 2;
        r.ky = yIs0[lane] ? 0 : yIs1[lane] ? 1 : 2;
        r.kz = zIs0[lane] ? 0 : zIs1[lane] ? 1 : 2;
        r.ox = ox[lane];
        r.oy = oy[lane];
        r.oz = oz[lane];
        r.sx = sx[lane];
        r.sy = sy[lane];
        r.sz = sz[lane];
        return r;
    }
    // Activates the valid rays among `lanes` (after their tMin/tMax are set)
    // and finds out whether they share one permutation.
    void activate(std::uint32_t lanes) {
        activeMask = lanes & validRays;
        uniform = activeMask != 0 && (uniformValid || sharePermutation(activeMask));
    }
    // Whether the lanes in `lanes` (not empty) share one permutation; if so,
    // sets kx, ky, kz to it.
    bool sharePermutation(std::uint32_t lanes);
};

// Every slot of `cluster` against every active lane of `rays`: mask[slot]
// holds the lanes hit with tMin < t < tMax, t/b1/b2[slot][lane] their
// results (the same bits as intersectTriangleWatertight for that lane).
struct PacketHits {
    std::uint32_t mask[kClusterTriangles];
    alignas(32) float t[kClusterTriangles][WatertightRayPacket::kLanes];
    alignas(32) float b1[kClusterTriangles][WatertightRayPacket::kLanes];
    alignas(32) float b2[kClusterTriangles][WatertightRayPacket::kLanes];
};
// Returns whether any slot was hit.
bool intersectPacketWatertight(const WatertightRayPacket& rays, const TriangleCluster& cluster, PacketHits& out);

}  // namespace rtlab::tracer
