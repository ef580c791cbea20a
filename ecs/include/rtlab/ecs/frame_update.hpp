#pragma once
// What changed in one World::update(), as the acceleration-structure manager
// needs it (Falcor-style update flags):
//   moved instance        -> TLAS update only
//   deformed mesh         -> BLAS refit (same topology)
//   new / re-topologised  -> BLAS rebuild
// Entities and meshes untouched this frame appear in no list.
#include <rtlab/ecs/assets.hpp>
#include <rtlab/ecs/entity.hpp>

#include <cstdint>
#include <vector>

namespace rtlab::ecs {

struct FrameUpdate {
    std::uint32_t frame = 0;  // 0 for the first update
    float time = 0.f;         // seconds since the world started

    std::vector<Entity> movedInstances;  // MeshInstance entities whose world transform changed
    std::vector<MeshId> refitMeshes;     // vertices changed, topology kept
    std::vector<MeshId> rebuiltMeshes;   // created, or topology changed
    bool instanceSetChanged = false;     // instances added or removed (TLAS rebuild)
    bool lightsChanged = false;
    bool camerasChanged = false;
    bool materialsChanged = false;

    bool geometryChanged() const {
        return !movedInstances.empty() || !refitMeshes.empty() || !rebuiltMeshes.empty() || instanceSetChanged;
    }
};

}  // namespace rtlab::ecs
