// Ray reordering before warp formation (gpu.rayOrder = directionOrigin): the
// batch is stably sorted by a 63-bit key before it is cut into warps, so that
// a warp holds rays that start near each other and travel the same way.
// This models the ray sorting/binning that precedes warp formation in
// software and hardware reordering schemes (Garanzha & Loop 2010, "Fast ray
// sorting and breadth-first packet traversal for GPU ray tracing": rays
// binned by origin cell and direction; Pharr et al. 1997 / Moon et al. 2010
// order rays by direction and origin for coherence):
//
//   key = octant of the direction (3 bits: signs of x, y, z)
//         | Morton code of the origin, 10 bits per axis, in the batch's origin bounds
//         | Morton code of the direction's first two components after the octant,
//           15 bits each, mapped from [-1, 1]
//
// Hits do not change (each ray is traced exactly as submitted); cycles do.
#include "../ray_order.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace rtlab::rtcore_sim {
namespace {

std::uint64_t spread3(std::uint64_t v) {  // 10 bits -> every third bit
    v &= 0x3ff;
    v = (v | v << 16) & 0x30000ff;
    v = (v | v << 8) & 0x300f00f;
    v = (v | v << 4) & 0x30c30c3;
    v = (v | v << 2) & 0x9249249;
    return v;
}

std::uint64_t spread2(std::uint64_t v) {  // 15 bits -> every second bit
    v &= 0x7fff;
    v = (v | v << 8) & 0x00ff00ff;
    v = (v | v << 4) & 0x0f0f0f0f;
    v = (v | v << 2) & 0x33333333;
    v = (v | v << 1) & 0x55555555;
    return v;
}

std::uint64_t quantize(float x, float lo, float hi, std::uint32_t levels) {
    if (!(hi > lo) || !std::isfinite(x)) return 0;
    const float t = (x - lo) / (hi - lo);
    return static_cast<std::uint64_t>(std::clamp(t, 0.f, 1.f) * float(levels - 1) + 0.5f);
}

}  // namespace

std::vector<std::uint64_t> directionOriginKeys(std::span<const SimRay> rays) {
    // Step: the batch's origin bounds (finite origins only).
    vec3 lo(kInfinity), hi(-kInfinity);
    for (const SimRay& r : rays)
        if (std::isfinite(r.ray.origin.x) && std::isfinite(r.ray.origin.y) && std::isfinite(r.ray.origin.z)) {
            lo = glm::min(lo, r.ray.origin);
            hi = glm::max(hi, r.ray.origin);
        }
    // Step: one key per ray.
    std::vector<std::uint64_t> keys(rays.size());
    for (std::size_t i = 0; i < rays.size(); ++i) {
        const vec3& o = rays[i].ray.origin;
        const vec3& d = rays[i].ray.direction;
        const std::uint64_t octant = (d.x < 0.f ? 4u : 0u) | (d.y < 0.f ? 2u : 0u) | (d.z < 0.f ? 1u : 0u);
        const std::uint64_t origin = spread3(quantize(o.x, lo.x, hi.x, 1024)) << 2 |
                                     spread3(quantize(o.y, lo.y, hi.y, 1024)) << 1 |
                                     spread3(quantize(o.z, lo.z, hi.z, 1024));
        const float len = std::max(std::abs(d.x) + std::abs(d.y) + std::abs(d.z), 1e-30f);
        const std::uint64_t direction =
            spread2(quantize(d.x / len, -1.f, 1.f, 32768)) << 1 | spread2(quantize(d.y / len, -1.f, 1.f, 32768));
        keys[i] = octant << 60 | origin << 30 | direction;
    }
    return keys;
}

std::vector<std::uint32_t> directionOriginOrder(std::span<const SimRay> rays) {
    const std::vector<std::uint64_t> keys = directionOriginKeys(rays);
    std::vector<std::uint32_t> order(rays.size());
    std::iota(order.begin(), order.end(), 0u);
    std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
    return order;
}

}  // namespace rtlab::rtcore_sim
