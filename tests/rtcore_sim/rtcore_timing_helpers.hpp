#pragma once
// Shared pieces of the timing-model tests: micro scenes and ray batches.
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim::test_support {

inline ecs::Geometry oneTriangleGeometry(const vec3& p0, const vec3& p1, const vec3& p2) {
    ecs::Geometry g;
    g.positions = {p0, p1, p2};
    g.normals.assign(3, vec3(0.f, 0.f, 1.f));
    g.indices = {0, 1, 2};
    return g;
}

inline ModelRay makeModelRay(const vec3& origin, const vec3& direction, float tMin = 0.f, float tMax = kInfinity) {
    ModelRay r;
    r.origin = origin;
    r.direction = direction;
    r.tMin = tMin;
    r.tMax = tMax;
    return r;
}

inline SimRay simRay(const ModelRay& ray, std::uint32_t rayType = 0) {
    SimRay r;
    r.ray = ray;
    r.rayType = rayType;
    return r;
}

// A world plus the model scene built from it with `params`.
struct MicroScene {
    ecs::World world;
    std::unique_ptr<ModelScene> model;
    ecs::SceneSnapshot snapshot;

    void build(const BvhParams& params) {
        model = std::make_unique<ModelScene>(params);
        snapshot = ecs::makeSnapshot(world, world.update(0.f));
        model->update(snapshot);
    }
};

// One triangle (0,0,0) (1,0,0) (0,1,0) instanced once at z = -2: both roots are leaves.
inline void makeOneTriangleScene(MicroScene& scene, const BvhParams& params) {
    scene.world.addMaterial({});
    const ecs::MeshId mesh = scene.world.addMesh(
        ecs::load::makeMesh("tri", oneTriangleGeometry(vec3(0.f), vec3(1.f, 0.f, 0.f), vec3(0.f, 1.f, 0.f))));
    const ecs::Entity e = scene.world.create("tri");
    scene.world.emplace(e, ecs::LocalTransform{vec3(0.f, 0.f, -2.f)});
    scene.world.emplace(e, ecs::MeshInstance{mesh});
    scene.build(params);
}

// Primary rays through the pixel centres of the scene's camera.
inline std::vector<SimRay> primaryRays(const ecs::CameraSnapshot& camera, int width, int height,
                                       std::uint32_t rayType = 0) {
    std::vector<SimRay> rays;
    rays.reserve(std::size_t(width) * height);
    const float aspect = camera.camera.aspectRatio > 0.f ? camera.camera.aspectRatio : float(width) / float(height);
    const float tanHalf = std::tan(0.5f * camera.camera.yfov);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const float sx = (2.f * (x + 0.5f) / width - 1.f) * tanHalf * aspect;
            const float sy = (1.f - 2.f * (y + 0.5f) / height) * tanHalf;
            ModelRay ray;
            ray.origin = vec3(camera.worldFromCamera[3]);
            ray.direction = glm::normalize(mat3(camera.worldFromCamera) * glm::normalize(vec3(sx, sy, -1.f)));
            rays.push_back(simRay(ray, rayType));
        }
    return rays;
}

// A loaded builtin scene (frame 0) and its model scene.
inline void loadScene(MicroScene& scene, const std::string& source, const BvhParams& params) {
    ecs::load::loadScene(scene.world, source);
    scene.build(params);
}

inline bool sameHit(const ModelHit& a, const ModelHit& b) {
    return a.hit == b.hit && (!a.hit || (a.t == b.t && a.instanceIndex == b.instanceIndex &&
                                         a.geometryIndex == b.geometryIndex && a.primitiveIndex == b.primitiveIndex &&
                                         a.b1 == b.b1 && a.b2 == b.b2 && a.procedural == b.procedural));
}

inline bool sameWork(const TraversalCounters& a, const TraversalCounters& b) {
    return a.steps == b.steps && a.nodeVisits == b.nodeVisits && a.leafVisits == b.leafVisits &&
           a.boxTests == b.boxTests && a.triangleTests == b.triangleTests && a.proceduralTests == b.proceduralTests &&
           a.instanceTransitions == b.instanceTransitions && a.anyHitCalls == b.anyHitCalls &&
           a.intersectionCalls == b.intersectionCalls && a.maxStackDepth == b.maxStackDepth;
}

// Runs `rays` as one batch with the opaque side.
inline std::vector<SimRayResult> runBatch(RtCore& core, const std::vector<SimRay>& rays) {
    OpaqueSide side;
    std::vector<SimRayResult> results(rays.size());
    core.run(rays, side, results);
    return results;
}

}  // namespace rtlab::rtcore_sim::test_support
