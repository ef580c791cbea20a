#pragma once
// DXR vocabulary: ray flags, instance flags, hit kinds, ray descriptions and
// hit attributes, with the numeric values of the DXR specification.
#include <rtlab/core/math.hpp>

#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace rtlab::tracer {

// RAY_FLAG_* (D3D12_RAY_FLAGS).
namespace RayFlag {
inline constexpr std::uint32_t None = 0x00;
inline constexpr std::uint32_t ForceOpaque = 0x01;
inline constexpr std::uint32_t ForceNonOpaque = 0x02;
inline constexpr std::uint32_t AcceptFirstHitAndEndSearch = 0x04;
inline constexpr std::uint32_t SkipClosestHitShader = 0x08;
inline constexpr std::uint32_t CullBackFacingTriangles = 0x10;
inline constexpr std::uint32_t CullFrontFacingTriangles = 0x20;
inline constexpr std::uint32_t CullOpaque = 0x40;
inline constexpr std::uint32_t CullNonOpaque = 0x80;
inline constexpr std::uint32_t SkipTriangles = 0x100;
inline constexpr std::uint32_t SkipProceduralPrimitives = 0x200;
}  // namespace RayFlag

// D3D12_RAYTRACING_INSTANCE_FLAG_*.
namespace InstanceFlag {
inline constexpr std::uint8_t None = 0x0;
inline constexpr std::uint8_t TriangleCullDisable = 0x1;
inline constexpr std::uint8_t TriangleFrontCounterClockwise = 0x2;
inline constexpr std::uint8_t ForceOpaque = 0x4;
inline constexpr std::uint8_t ForceNonOpaque = 0x8;
}  // namespace InstanceFlag

// HitKind() values for triangles; procedural hits report their own (0..127).
inline constexpr std::uint32_t kHitKindTriangleFrontFace = 254;
inline constexpr std::uint32_t kHitKindTriangleBackFace = 255;

// RayDesc: the ray covers the open interval (tMin, tMax).
struct RayDesc {
    vec3 origin{0.f};
    float tMin = 0.f;
    vec3 direction{0.f, 0.f, -1.f};
    float tMax = kInfinity;
};

// The largest origin or direction coordinate a ray may have: Embree's
// FLT_LARGE (it asserts, or traverses garbage, beyond it). No float ray
// tracer can place a hit that far out anyway.
inline constexpr float kLargestRayCoordinate = 1.844e18f;

// DXR leaves rays with a non-finite origin or direction, a negative or NaN
// TMin, or TMax < TMin undefined; every rtlab back end counts them as
// misses, and so rays with a coordinate beyond kLargestRayCoordinate (a
// replayed file or a scene at absurd coordinates can hold such rays).
inline bool isValidRay(const RayDesc& r) {
    const auto inRange = [](const vec3& v) {
        return std::fabs(v.x) <= kLargestRayCoordinate && std::fabs(v.y) <= kLargestRayCoordinate &&
               std::fabs(v.z) <= kLargestRayCoordinate;  // false for NaN and infinity
    };
    return inRange(r.origin) && inRange(r.direction) && r.tMin >= 0.f && r.tMax >= r.tMin;
}

// Hit attributes: barycentrics for triangles (u = weight of vertex 1,
// v = weight of vertex 2), or up to 8 floats from an intersection shader
// (DXR's 32-byte attribute limit).
// Coherent rays (camera rays of a tile) share their traversal; incoherent
// ones (bounces) go their own ways. A hint to Embree; results are the same.
enum class RayCoherence { Coherent, Incoherent };

struct HitAttributes {
    std::array<float, 8> values{};
    vec2 barycentrics() const { return {values[0], values[1]}; }
};

enum class AnyHitResult : std::uint8_t {
    Accept,              // commit; t becomes the new TMax; traversal goes on
    Ignore,              // IgnoreHit(): as if this candidate did not exist (payload changes stay)
    AcceptAndEndSearch,  // AcceptHitAndEndSearch(): commit and stop traversal
};

// Errors that the pipeline reports instead of undefined behaviour.
class PipelineError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

}  // namespace rtlab::tracer
