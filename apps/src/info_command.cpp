#include "commands.hpp"

#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/session/frame_session.hpp>

#include <cstdio>

namespace rtlab::app {

void addInfoCommand(CLI::App& app, InfoOptions& o) {
    CLI::App* cmd = app.add_subcommand("info", "Print what a scene contains");
    cmd->add_option("--scene", o.scene, "builtin:NAME, .gltf/.glb, or scene .json")->required();
}

int runInfo(const InfoOptions& o) {
    session::FrameOptions options;
    options.scene = o.scene;
    session::FrameSession s(options, session::Stages::Plan);
    s.load();
    const ecs::World& world = s.world();

    std::size_t triangles = 0, instancedTriangles = 0, degenerate = 0;
    for (const ecs::MeshAsset& m : world.meshes()) {
        triangles += m.triangleCount();
        degenerate += ecs::load::degenerateTriangleCount(m);
    }
    world.each<ecs::MeshInstance>([&](ecs::Entity, const ecs::MeshInstance& inst) {
        instancedTriangles += world.mesh(inst.mesh).triangleCount();
    });
    std::size_t lightsByType[5] = {};
    world.each<ecs::Light>([&](ecs::Entity, const ecs::Light& l) { ++lightsByType[static_cast<int>(l.type)]; });
    std::size_t masked = 0, transmissive = 0, glossy = 0, emissive = 0;
    for (const ecs::Material& m : world.materials()) {
        masked += m.alphaMode == ecs::AlphaMode::Mask;
        transmissive += m.transmission > 0.f;
        glossy += m.roughness <= 0.3f;
        emissive += glm::length(m.emissive) > 0.f;
    }
    std::size_t deformable = 0;
    for (const ecs::MeshAsset& m : world.meshes())
        for (const ecs::Geometry& g : m.geometries)
            if (g.deformable()) {
                ++deformable;
                break;
            }

    std::printf("scene: %s\n", o.scene.c_str());
    const ecs::SceneSettings& settings = world.settings();
    if (!settings.parameters.empty()) {
        std::printf("parameters:");
        for (const auto& [key, value] : settings.parameters) std::printf(" %s=%u", key.c_str(), value);
        std::printf("\n");
    }
    if (!settings.generated.empty()) std::printf("generated: %s\n", settings.generated.c_str());
    std::printf("entities: %u\n", world.entityCount());
    std::printf("meshes: %zu (%zu deformable)\n", world.meshes().size(), deformable);
    std::printf("instances: %zu\n", world.count<ecs::MeshInstance>());
    std::printf("triangles: %zu unique, %zu instanced, %zu of the unique degenerate (zero area)\n", triangles,
                instancedTriangles, degenerate);
    std::printf("materials: %zu (%zu alpha-masked, %zu transmissive, %zu with roughness <= 0.3, %zu emissive)\n",
                world.materials().size(), masked, transmissive, glossy, emissive);
    std::printf("textures: %zu\n", world.textures().size());
    std::printf("lights: %zu (point %zu, spot %zu, directional %zu, rect %zu, sphere %zu)\n", world.count<ecs::Light>(),
                lightsByType[0], lightsByType[1], lightsByType[2], lightsByType[3], lightsByType[4]);
    std::printf("cameras: %zu\n", world.count<ecs::Camera>());
    std::printf("skins: %zu\n", world.count<ecs::Skin>());
    std::printf("volumes: %zu\n", world.count<ecs::Volume>());
    std::printf("animations: %zu, length %.3f s\n", world.animations().size(), world.animationDuration());
    const ecs::LoadReport& report = world.loadReport();
    std::printf("skipped primitives: %u points, %u lines (triangles only)\n", report.skippedPointPrimitives,
                report.skippedLinePrimitives);
    const Aabb b = ecs::load::worldBounds(world);
    if (!b.empty()) std::printf("bounds: [%g %g %g] - [%g %g %g]\n", b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z);
    return 0;
}

}  // namespace rtlab::app
