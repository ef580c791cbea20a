#pragma once
// A scene loaded once and frozen at time 0 (a static view), with its
// acceleration structures: what the denoise-quality tests render from.
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <string>

namespace rtlab::test {

struct StaticView {
    ecs::World world;
    ecs::SceneSnapshot scene;
    tracer::AccelManager accel;

    explicit StaticView(const std::string& source) {
        ecs::load::loadScene(world, source);
        scene = ecs::makeSnapshot(world, world.update(0.f));
        accel.update(scene);
    }
};

}  // namespace rtlab::test
