#pragma once
// Which of two triangle hits at the same distance is the closest: DXR leaves
// it open, rtlab fixes it so that the committed hit never depends on
// traversal order (and so is the same on every back end). A candidate at t
// replaces the committed hit when t < tCommitted, or when t == tCommitted
// and its (instance, geometry, primitive) is smaller. Ties happen where two
// triangles share an edge or vertex and where surfaces of different
// instances touch (the corners of a room).
#include <rtlab/core/math.hpp>

#include <bit>
#include <cmath>
#include <compare>
#include <cstdint>

namespace rtlab::tracer {

struct HitId {
    std::uint32_t instance = 0, geometry = 0, primitive = 0;
    auto operator<=>(const HitId&) const = default;
};

// The exclusive upper end to test a candidate against: one float past the
// committed t, so that ties reach hitReplaces (before any commit, pass the
// ray's TMax itself).
inline float tieInclusiveUpperBound(float tCommitted) {
    // The next float up: one step of the bit pattern for finite t >= 0 (the hot case).
    if (tCommitted >= 0.f && tCommitted < kInfinity)
        return std::bit_cast<float>(std::bit_cast<std::uint32_t>(tCommitted) + 1u);
    return std::nextafter(tCommitted, kInfinity);
}

// A candidate with t <= tCommitted (found by a test bounded by
// tieInclusiveUpperBound) replaces the committed hit.
inline bool hitReplaces(float t, const HitId& candidate, float tCommitted, const HitId& committed) {
    return t < tCommitted || candidate < committed;
}

}  // namespace rtlab::tracer
