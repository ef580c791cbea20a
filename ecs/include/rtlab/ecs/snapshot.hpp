#pragma once
// The plain, read-only view of one frame that tracer/ and rtcore_sim/
// consume: they never see World internals (DESIGN.md rules of the house).
#include <rtlab/ecs/assets.hpp>
#include <rtlab/ecs/components.hpp>
#include <rtlab/ecs/frame_update.hpp>

#include <memory>
#include <vector>

namespace rtlab::ecs {

class World;
class VolumeGrid;

struct InstanceSnapshot {
    Entity entity;
    MeshId mesh = 0;
    mat4 worldFromObject{1.f};
    std::uint8_t mask = 0xff;
    std::uint8_t flags = 0;                                   // DXR instance flags
    std::uint32_t instanceId = 0;                             // DXR InstanceID()
    std::uint32_t hitGroupOffset = MeshInstance::kAutomatic;  // InstanceContributionToHitGroupIndex
};

struct LightSnapshot {
    Entity entity;
    Light light;
    mat4 worldFromLight{1.f};  // emits along -Z; rect spans local XY
};

struct CameraSnapshot {
    Camera camera;
    mat4 worldFromCamera{1.f};  // looks down -Z, +Y up
};

struct VolumeSnapshot {
    Entity entity;
    Volume volume;
    std::shared_ptr<const VolumeGrid> grid;
};

struct SceneSnapshot {
    const std::vector<MeshAsset>* meshes = nullptr;
    const std::vector<Material>* materials = nullptr;
    const std::vector<Texture>* textures = nullptr;
    std::vector<InstanceSnapshot> instances;  // in a stable order (entity index)
    std::vector<LightSnapshot> lights;
    std::vector<VolumeSnapshot> volumes;
    CameraSnapshot camera;
    FrameUpdate update;
    // Mesh instances left out of `instances` because no back end can trace
    // them: a non-finite or singular transform (a zero scale on some axis),
    // or one scaling by more than kMaxInstanceScale either way (Embree's
    // object-space rays would leave its valid range; it asserts).
    std::uint32_t untraceableInstances = 0;
};

inline constexpr double kMaxInstanceScale = 1e12;

// Snapshot of `world` after an update() that returned `update`.
SceneSnapshot makeSnapshot(const World& world, FrameUpdate update);

}  // namespace rtlab::ecs
