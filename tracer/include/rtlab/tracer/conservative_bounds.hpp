#pragma once
// Conservative box tests at any magnitude (docs/acceleration-structures.md,
// "Conservative traversal"). A float slab test computes (plane - origin) / d,
// or plane / d - origin / d as Embree's fast path does; either way its
// rounding error, as a distance along the ray, grows with the magnitude of
// the coordinates involved: the box's and the ray origin's. A box padded by
// a fixed multiple of float rounding at that magnitude is never missed by a
// ray that hits the unpadded box, and a triangle tied with the committed hit
// (hit_order.hpp) is always reached. Both traversal back ends pad by this one
// rule: Embree's user-geometry boxes at build time (from a bound on the ray
// origins, AccelManager), the RT-core model per ray at traversal time.
#include <rtlab/core/math.hpp>

#include <algorithm>
#include <cmath>

namespace rtlab::tracer {

// 64 units of float rounding (2^-24) per unit of coordinate magnitude: the
// slab test, the instance transform and the triangle test each err by a few.
inline constexpr float kBoxPaddingPerMagnitude = 0x1p-18f;

// Padding of a box whose coordinates are at most `boxMagnitude` in absolute
// value, tested by rays whose origin coordinates are at most `originMagnitude`.
inline float conservativeBoxPadding(float boxMagnitude, float originMagnitude) {
    return kBoxPaddingPerMagnitude * (boxMagnitude + originMagnitude);
}

inline float maxAbsCoordinate(const vec3& p) { return std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)}); }
// 0 for an empty box.
inline float maxAbsCoordinate(const Aabb& b) {
    return b.empty() ? 0.f : std::max(maxAbsCoordinate(b.lo), maxAbsCoordinate(b.hi));
}

using rtlab::maxNormGain;  // moved to core/math.hpp; kept here for code that names it in this namespace

}  // namespace rtlab::tracer
