#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>

#include <algorithm>

namespace rtlab::ecs {

SceneSnapshot makeSnapshot(const World& world, FrameUpdate update) {
    SceneSnapshot s;
    s.meshes = &world.meshes();
    s.materials = &world.materials();
    s.textures = &world.textures();
    world.each<MeshInstance>([&](Entity e, const MeshInstance& inst) {
        const std::uint32_t id = inst.instanceId == MeshInstance::kAutomatic ? e.index : inst.instanceId;
        s.instances.push_back({e, inst.mesh, world.instanceWorldFromObject(e), inst.mask, inst.flags, id & 0xffffffu,
                               inst.hitGroupOffset});
    });
    // Stable order independent of component-store history.
    std::sort(s.instances.begin(), s.instances.end(),
              [](const InstanceSnapshot& a, const InstanceSnapshot& b) { return a.entity.index < b.entity.index; });
    world.each<Light, WorldTransform>([&](Entity e, const Light& l, const WorldTransform& w) {
        s.lights.push_back({e, l, w.worldFromObject});
    });
    std::sort(s.lights.begin(), s.lights.end(),
              [](const LightSnapshot& a, const LightSnapshot& b) { return a.entity.index < b.entity.index; });
    world.each<Volume>([&](Entity e, const Volume& v) {
        if (v.grid < world.volumeGrids().size()) s.volumes.push_back({e, v, world.volumeGrids()[v.grid]});
    });
    if (const Camera* cam = world.get<Camera>(world.activeCamera())) {
        s.camera.camera = *cam;
        s.camera.worldFromCamera = world.get<WorldTransform>(world.activeCamera())->worldFromObject;
    }
    s.update = std::move(update);
    return s;
}

}  // namespace rtlab::ecs
