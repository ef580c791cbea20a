#pragma once
// Ray workloads for studying the model outside a renderer (tests, perf/):
// secondary rays derived from a batch's hits, deterministic (stateless hash
// of the ray's index, DESIGN.md "Determinism").
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>

#include <cstdint>
#include <vector>

namespace rtlab::rtcore_sim {

// One cosine-weighted diffuse bounce from every hit of `rays` (hits[i] is
// the hit of rays[i]): origin on the hit triangle, offset along the
// geometric normal facing the incoming ray by 1e-4 (1 + |p|), direction
// cosine-distributed around that normal with the random numbers of
// SampleKey{pixel = i, bounce = 1, seed}. Misses and procedural hits give no
// ray. The new rays have `rayType`.
std::vector<SimRay> diffuseBounceRays(const ecs::SceneSnapshot& scene, const std::vector<SimRay>& rays,
                                      const std::vector<ModelHit>& hits, std::uint32_t rayType = 1,
                                      std::uint32_t seed = 0);

}  // namespace rtlab::rtcore_sim
