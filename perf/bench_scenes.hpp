#pragma once
// Scene set-up shared by the benchmarks.
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <memory>
#include <string>

namespace rtlab::bench {

// A loaded scene after its first update, with built acceleration structures.
struct LoadedScene {
    ecs::World world;
    ecs::SceneSnapshot snapshot;
    std::unique_ptr<tracer::AccelManager> accel;

    explicit LoadedScene(const std::string& source, tracer::AccelOptions options = {}) {
        ecs::load::loadScene(world, source);
        snapshot = ecs::makeSnapshot(world, world.update(0.f));
        accel = std::make_unique<tracer::AccelManager>(options);
        accel->update(snapshot);
    }
    // The scene's camera for one image size (build it outside per-pixel loops).
    shaders::PinholeCamera camera(int width, int height) const { return {snapshot.camera, width, height}; }
};

// The primary ray through the centre of pixel (x, y).
inline tracer::RayDesc primaryRay(const shaders::PinholeCamera& camera, int x, int y) {
    const shaders::CameraRay r = camera.ray(x + 0.5f, y + 0.5f);
    return {r.origin, 0.f, r.direction, kInfinity};
}

}  // namespace rtlab::bench
