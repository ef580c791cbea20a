#pragma once
// Sparse-set component storage: components live contiguously in `dense`
// order; `sparse` maps an entity index to its dense slot. Removal swaps the
// last element in, so iteration stays over a packed array.
#include <rtlab/ecs/entity.hpp>

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace rtlab::ecs {

template <class T>
class ComponentStore {
public:
    static constexpr std::uint32_t kNoSlot = std::numeric_limits<std::uint32_t>::max();

    bool contains(Entity e) const {
        return e.index < sparse_.size() && sparse_[e.index] != kNoSlot && entities_[sparse_[e.index]] == e;
    }
    T* find(Entity e) { return contains(e) ? &components_[sparse_[e.index]] : nullptr; }
    const T* find(Entity e) const { return contains(e) ? &components_[sparse_[e.index]] : nullptr; }

    // Inserts or replaces the component of `e`.
    T& set(Entity e, T value) {
        if (T* existing = find(e)) return *existing = std::move(value);
        if (e.index >= sparse_.size()) sparse_.resize(e.index + 1, kNoSlot);
        sparse_[e.index] = static_cast<std::uint32_t>(entities_.size());
        entities_.push_back(e);
        components_.push_back(std::move(value));
        return components_.back();
    }
    bool remove(Entity e) {
        if (!contains(e)) return false;
        const std::uint32_t slot = sparse_[e.index];
        const std::uint32_t last = static_cast<std::uint32_t>(entities_.size() - 1);
        if (slot != last) {
            entities_[slot] = entities_[last];
            components_[slot] = std::move(components_[last]);
            sparse_[entities_[slot].index] = slot;
        }
        entities_.pop_back();
        components_.pop_back();
        sparse_[e.index] = kNoSlot;
        return true;
    }
    std::size_t size() const { return entities_.size(); }
    std::span<const Entity> entities() const { return entities_; }
    std::span<const T> components() const { return components_; }

private:
    std::vector<std::uint32_t> sparse_;
    std::vector<Entity> entities_;
    std::vector<T> components_;
};

}  // namespace rtlab::ecs
