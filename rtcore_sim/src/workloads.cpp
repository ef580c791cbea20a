#include <rtlab/rtcore_sim/workloads.hpp>

#include <rtlab/core/rng.hpp>

#include <cmath>

namespace rtlab::rtcore_sim {

std::vector<SimRay> diffuseBounceRays(const ecs::SceneSnapshot& scene, const std::vector<SimRay>& rays,
                                      const std::vector<ModelHit>& hits, std::uint32_t rayType, std::uint32_t seed) {
    std::vector<SimRay> out;
    for (std::size_t i = 0; i < rays.size() && i < hits.size(); ++i) {
        const ModelHit& h = hits[i];
        if (!h.hit || h.procedural) continue;
        // Step: the geometric normal in world space, facing the incoming ray.
        const ecs::InstanceSnapshot& inst = scene.instances[h.instanceIndex];
        const ecs::Geometry& g = (*scene.meshes)[inst.mesh].geometries[h.geometryIndex];
        const vec3 p0 = g.positions[g.indices[3 * h.primitiveIndex]];
        const vec3 p1 = g.positions[g.indices[3 * h.primitiveIndex + 1]];
        const vec3 p2 = g.positions[g.indices[3 * h.primitiveIndex + 2]];
        const mat3 normalFromObject = glm::transpose(glm::inverse(mat3(inst.worldFromObject)));
        vec3 n = glm::normalize(normalFromObject * glm::cross(p1 - p0, p2 - p0));
        if (!isFinite(n)) continue;  // degenerate triangle
        const vec3 d = rays[i].ray.direction;
        if (glm::dot(n, d) > 0.f) n = -n;
        const vec3 p = rays[i].ray.origin + h.t * d;
        // Step: cosine-weighted direction around n.
        const SampleKey key{static_cast<std::uint32_t>(i), 0, 0, 1, seed};
        const float u1 = sampleUniform(key, 0), u2 = sampleUniform(key, 1);
        const float r = std::sqrt(u1), phi = 2.f * kPi * u2;
        const vec3 a = std::abs(n.x) > 0.5f ? vec3(0.f, 1.f, 0.f) : vec3(1.f, 0.f, 0.f);
        const vec3 tx = glm::normalize(glm::cross(a, n)), ty = glm::cross(n, tx);
        SimRay s;
        s.ray.origin = p + n * (1e-4f * (1.f + glm::length(p)));
        s.ray.direction = glm::normalize(r * std::cos(phi) * tx + r * std::sin(phi) * ty + std::sqrt(1.f - u1) * n);
        s.rayType = rayType;
        out.push_back(s);
    }
    return out;
}

}  // namespace rtlab::rtcore_sim
