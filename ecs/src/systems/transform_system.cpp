// Transform propagation: parents before children; an entity's world
// transform is recomputed only when its own local transform or an ancestor's
// world transform changed this update.
#include "../world_dirty_sets.hpp"

#include <algorithm>
#include <stdexcept>

namespace rtlab::ecs {

void World::rebuildHierarchyOrder() {
    const auto all = store<WorldTransform>().entities();
    const std::uint32_t capacity = entities_.indexCapacity();
    std::vector<std::int32_t> depth(capacity, -1);
    // Step: depth of every entity by walking up its parent chain (memoised);
    // a chain longer than the entity count is a cycle.
    std::vector<Entity> chain;
    for (Entity e : all) {
        chain.clear();
        Entity cur = e;
        while (depth[cur.index] < 0) {
            chain.push_back(cur);
            if (chain.size() > all.size()) throw std::logic_error("cycle in entity hierarchy");
            const Parent* p = get<Parent>(cur);
            if (!p || !alive(p->entity)) break;
            cur = p->entity;
        }
        std::int32_t d = depth[cur.index] >= 0 ? depth[cur.index] + 1 : 0;
        for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
            if (depth[it->index] < 0) depth[it->index] = d++;
            else d = depth[it->index] + 1;
        }
    }
    hierarchyOrder_.assign(all.begin(), all.end());
    std::stable_sort(hierarchyOrder_.begin(), hierarchyOrder_.end(), [&](Entity a, Entity b) {
        return depth[a.index] != depth[b.index] ? depth[a.index] < depth[b.index] : a.index < b.index;
    });
    hierarchyOrderValid_ = true;
}

void World::runTransformSystem(FrameUpdate& out) {
    if (!hierarchyOrderValid_) rebuildHierarchyOrder();
    auto& changed = dirty_->worldChanged;
    changed.assign(entities_.indexCapacity(), 0);
    for (Entity e : hierarchyOrder_) {
        const Parent* parent = get<Parent>(e);
        const bool parentChanged = parent && alive(parent->entity) && changed[parent->entity.index];
        if (!dirty_->transforms.contains(e.index) && !parentChanged) continue;

        const LocalTransform* local = get<LocalTransform>(e);
        mat4 world = local ? local->matrix() : mat4(1.f);
        if (parent && alive(parent->entity)) world = get<WorldTransform>(parent->entity)->worldFromObject * world;

        WorldTransform* w = store<WorldTransform>().find(e);
        if (w->worldFromObject == world) continue;
        w->worldFromObject = world;
        changed[e.index] = 1;
        // A new instance is part of the TLAS rebuild, not a move.
        if (has<MeshInstance>(e) && !dirty_->newInstances.contains(e.index) && !has<Skin>(e))
            out.movedInstances.push_back(e);
        if (has<Light>(e)) out.lightsChanged = true;
        if (has<Camera>(e)) out.camerasChanged = true;
    }
}

}  // namespace rtlab::ecs
