#pragma once
// Shared pieces of the rtcore_sim tests: seeded random geometry and a
// brute-force closest-hit reference.
#include <rtlab/core/rng.hpp>
#include <rtlab/ecs/assets.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>
#include <rtlab/tracer/watertight_triangle.hpp>

#include <string>

namespace rtlab::rtcore_sim::test_support {

// Seeded uniform floats in [0, 1) from the PCG hash (same on every platform).
struct TestRandom {
    std::uint32_t state;
    explicit TestRandom(std::uint32_t seed) : state(pcgHash(seed ^ 0x5bd1e995u)) {}
    float next() {
        state = pcgHash(state);
        return static_cast<float>(state >> 8) * (1.0f / 16777216.0f);
    }
    float range(float lo, float hi) { return lo + (hi - lo) * next(); }
    vec3 point(float lo, float hi) { return {range(lo, hi), range(lo, hi), range(lo, hi)}; }
};

// `count` triangles scattered in [-extent, extent]^3, each with vertices
// within `size` of a random centre (no shared vertices).
inline ecs::Geometry makeTriangleSoup(std::uint32_t count, std::uint32_t seed, float extent = 1.f, float size = 0.3f) {
    TestRandom rng(seed);
    ecs::Geometry g;
    for (std::uint32_t t = 0; t < count; ++t) {
        const vec3 centre = rng.point(-extent, extent);
        for (int k = 0; k < 3; ++k) {
            g.indices.push_back(static_cast<std::uint32_t>(g.positions.size()));
            g.positions.push_back(centre + rng.point(-size, size));
            g.normals.push_back(vec3(0.f, 0.f, 1.f));
        }
    }
    return g;
}

inline ecs::MeshAsset makeSoupMesh(std::uint32_t count, std::uint32_t seed, float extent = 1.f, float size = 0.3f) {
    ecs::MeshAsset mesh;
    mesh.name = "soup " + std::to_string(seed);
    mesh.geometries.push_back(makeTriangleSoup(count, seed, extent, size));
    return mesh;
}

// Closest hit by testing every triangle of every instance, with the same
// object-space ray and triangle test (the tracer's watertight test) as the traversal.
inline ModelHit bruteForceClosestHit(const ModelScene& scene, const std::vector<ecs::MeshAsset>& meshes,
                                     const ModelRay& ray) {
    ModelHit best;
    float tClosest = ray.tMax;
    for (std::uint32_t i = 0; i < scene.instances().size(); ++i) {
        const ModelInstance& inst = scene.instances()[i];
        if ((ray.mask & inst.mask) == 0) continue;
        const vec3 origin = vec3(inst.objectFromWorld * glm::dvec4(glm::dvec3(ray.origin), 1.0));
        const vec3 direction = vec3(glm::dmat3(inst.objectFromWorld) * glm::dvec3(ray.direction));
        const ecs::MeshAsset& mesh = meshes[inst.mesh];
        for (std::uint32_t g = 0; g < mesh.geometries.size(); ++g) {
            const ecs::Geometry& geo = mesh.geometries[g];
            for (std::uint32_t t = 0; t < geo.triangleCount(); ++t) {
                const std::optional<tracer::TriangleHit> h = tracer::intersectTriangleWatertight(
                    origin, direction, geo.positions[geo.indices[3 * t]], geo.positions[geo.indices[3 * t + 1]],
                    geo.positions[geo.indices[3 * t + 2]], ray.tMin, tClosest);
                if (!h) continue;
                tClosest = h->t;
                best = ModelHit{true, h->t, i, g, t, 1.f - h->b1 - h->b2, h->b1, h->b2, false};
            }
        }
    }
    return best;
}

}  // namespace rtlab::rtcore_sim::test_support
