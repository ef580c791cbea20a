#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>

#include <algorithm>
#include <cmath>

namespace rtlab::ecs {

namespace {

// Finite, invertible, and scaling by at most kMaxInstanceScale either way.
bool traceable(const mat4& worldFromObject) {
    if (!isFinite(worldFromObject)) return false;
    const glm::dmat3 linear(mat3{worldFromObject});  // in double: a float determinant of tiny scales underflows
    if (!(std::abs(glm::determinant(linear)) > 0.0)) return false;
    const glm::dmat3 inverse = glm::inverse(linear);
    const double forward = maxNormGain(linear), backward = maxNormGain(inverse);
    return std::isfinite(backward) && forward <= kMaxInstanceScale && backward <= kMaxInstanceScale;
}

}  // namespace

SceneSnapshot makeSnapshot(const World& world, FrameUpdate update) {
    SceneSnapshot s;
    s.meshes = &world.meshes();
    s.materials = &world.materials();
    s.textures = &world.textures();
    world.each<MeshInstance>([&](Entity e, const MeshInstance& inst) {
        const std::uint32_t id = inst.instanceId == MeshInstance::kAutomatic ? e.index : inst.instanceId;
        const mat4 worldFromObject = world.instanceWorldFromObject(e);
        if (!traceable(worldFromObject)) {
            ++s.untraceableInstances;
            return;
        }
        s.instances.push_back(
            {e, inst.mesh, worldFromObject, inst.mask, inst.flags, id & 0xffffffu, inst.hitGroupOffset});
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
