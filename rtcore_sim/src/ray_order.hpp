#pragma once
// Ray orders applied to a batch before it is cut into warps (gpu.rayOrder;
// docs/rtcore-model.md, "GPU level"). Each lives in src/policies/order_*.cpp.
#include <rtlab/rtcore_sim/traversal.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace rtlab::rtcore_sim {

// order[i] = the index in `rays` of the i-th ray after sorting (a permutation;
// stable: equal keys keep their submission order).
std::vector<std::uint32_t> directionOriginOrder(std::span<const SimRay> rays);
// The sort key of every ray: direction octant, then origin Morton code (within
// the rays' origin bounds), then direction Morton code.
std::vector<std::uint64_t> directionOriginKeys(std::span<const SimRay> rays);

}  // namespace rtlab::rtcore_sim
