#pragma once
// Participating media (fog volumes) for the passes (internal). Extinction
// sigma_t(x) = densityScale x density(x); scattering = albedo x sigma_t;
// isotropic phase function. Only touched when the plan has the volumes
// pass: otherwise RenderContext::media is empty and every transmittance is 1.
#include <rtlab/core/rng.hpp>
#include <rtlab/ecs/snapshot.hpp>

#include <vector>

namespace rtlab::shaders::detail {

struct Medium {
    const ecs::VolumeGrid* grid = nullptr;
    float densityScale = 1.f;
    vec3 albedo{0.8f};
    Aabb bounds;
    float majorant = 0.f;  // densityScale x maxDensity
};
std::vector<Medium> mediaOf(const ecs::SceneSnapshot& scene);

// sigma_t at a world position.
float extinction(const Medium& medium, const vec3& position);

// The part [t0, t1] of the ray (o, d) inside `box` (empty when t0 >= t1).
bool clipToBox(const Aabb& box, const vec3& o, const vec3& d, float tMin, float tMax, float& t0, float& t1);

// Transmittance of every medium along (o, d) over [0, tMax]: ratio tracking
// against the majorant (unbiased) when it expects at most 64 collisions,
// otherwise 64 jittered midpoint steps of the optical depth (bounded work
// for any extinction; exp(-tau) underflows cleanly to 0). Finite, in [0, 1].
// Random numbers: `key` at dimensions dim, dim + 1, ...
float transmittance(const std::vector<Medium>& media, const vec3& o, const vec3& d, float tMax, const SampleKey& key,
                    std::uint32_t dim);

}  // namespace rtlab::shaders::detail
