#pragma once
// Private to ecs/src: the dirty sets behind World::patch() and friends.
#include <rtlab/ecs/world.hpp>

#include <algorithm>
#include <vector>

namespace rtlab::ecs {

// A set of small integers (entity indices, mesh ids) with O(1) insert and
// insertion-ordered listing.
class DirtyIndexSet {
public:
    void insert(std::uint32_t i) {
        if (i >= flags_.size()) flags_.resize(i + 1, 0);
        if (!flags_[i]) {
            flags_[i] = 1;
            list_.push_back(i);
        }
    }
    bool contains(std::uint32_t i) const { return i < flags_.size() && flags_[i]; }
    const std::vector<std::uint32_t>& list() const { return list_; }
    bool empty() const { return list_.empty(); }
    void clear() {
        for (std::uint32_t i : list_) flags_[i] = 0;
        list_.clear();
    }

private:
    std::vector<std::uint8_t> flags_;
    std::vector<std::uint32_t> list_;
};

struct World::DirtySets {
    DirtyIndexSet transforms;    // entity indices whose LocalTransform/Parent changed
    DirtyIndexSet morphWeights;  // entity indices whose MorphWeights changed
    DirtyIndexSet skins;         // entity indices whose Skin changed
    DirtyIndexSet newInstances;  // entity indices that gained a MeshInstance
    DirtyIndexSet refitMeshes;
    DirtyIndexSet rebuiltMeshes;
    std::vector<std::uint8_t> worldChanged;  // per entity index, this update (transform system output)
    bool instanceSet = false;
    bool lights = false;
    bool cameras = false;
    bool materials = false;
    bool volumes = false;

    void clear() {
        transforms.clear();
        morphWeights.clear();
        skins.clear();
        newInstances.clear();
        refitMeshes.clear();
        rebuiltMeshes.clear();
        instanceSet = lights = cameras = materials = volumes = false;
    }
};

}  // namespace rtlab::ecs
