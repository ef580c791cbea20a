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
#include <bit>
#include <vector>
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
inline std::optional<TriangleHit> intersectTriangleWatertight(const vec3& origin, const vec3& direction,
                                                              const vec3& p0, const vec3& p1, const vec3& p2,
                                                              float tMin, float tMax) {
    return intersectTriangleWatertight(makeWatertightRay(origin, direction), p0, p1, p2, tMin, tMax);
}

// Up to kClusterTriangles triangles of one geometry, packed (PackedClusters)
// as floats: [count, primitive id per slot, v[vertex][axis][slot]] with count
// and the ids bit-cast, the coordinates in structure-of-arrays form with a
// row of `count` floats per (vertex, axis). A cluster of n triangles takes
// 1 + 10 n floats rounded up to 16 bytes (48 / 96 / 128 / 176 bytes): the
// terrain's clusters (1.7 triangles on average) took 176 bytes each when
// every cluster had four slots, twice Embree's whole BVH per triangle, and
// the first touch of a cluster was most of a callback's time.
inline constexpr int kClusterTriangles = 4;
struct TriangleCluster {
    const float* data = nullptr;
    std::uint32_t count = 0;

    std::uint32_t primitive(std::uint32_t slot) const { return std::bit_cast<std::uint32_t>(data[1 + slot]); }
    // The `count` coordinates `axis` of vertex k; a 4-wide load from here
    // stays inside the packed array (PackedClusters keeps 4 floats of tail).
    const float* row(int k, int axis) const { return data + 1 + count + (k * 3 + axis) * count; }
    float coordinate(int k, int axis, int slot) const { return row(k, axis)[slot]; }
    vec3 vertex(int slot, int k) const { return vec3(coordinate(k, 0, slot), coordinate(k, 1, slot), coordinate(k, 2, slot)); }
};

// The clusters of one geometry in one array of 16-byte units. A cluster is
// addressed by the unit it starts at, which is also its Embree primitive id:
// the callbacks reach it without an index table, and the units inside a
// cluster are primitives with an empty box, which Embree's builders skip.
class PackedClusters {
public:
    static constexpr std::uint32_t unitsFor(std::uint32_t triangles) { return (1 + 10 * triangles + 3) / 4; }
    // Appends a cluster of `count` (1..kClusterTriangles) triangles with ids
    // `primitives`, vertices unset; returns its unit.
    std::uint32_t append(const std::uint32_t* primitives, std::uint32_t count);
    void setTriangle(std::uint32_t unit, std::uint32_t slot, const vec3& p0, const vec3& p1, const vec3& p2);
    void clear() {
        floats_.assign(4, 0.f);
        isStart_.clear();
    }

    TriangleCluster at(std::uint32_t unit) const {
        const float* d = floats_.data() + 4 * std::size_t(unit);
        return {d, std::bit_cast<std::uint32_t>(d[0])};
    }
    bool startsCluster(std::uint32_t unit) const { return unit < isStart_.size() && isStart_[unit]; }
    // The unit after the cluster starting at `unit` (clusters lie back to back).
    std::uint32_t next(std::uint32_t unit) const { return unit + unitsFor(at(unit).count); }
    std::uint32_t units() const { return static_cast<std::uint32_t>(isStart_.size()); }
    std::uint64_t bytes() const { return floats_.size() * sizeof(float) + isStart_.size(); }

private:
    std::vector<float> floats_ = std::vector<float>(4, 0.f);  // the units, then 4 floats of tail
    std::vector<std::uint8_t> isStart_;
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
