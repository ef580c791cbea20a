#pragma once
// Entity handles with generation counters: a handle to a destroyed entity is
// detected (alive() is false), never dereferenced.
#include <cstdint>
#include <limits>
#include <vector>

namespace rtlab::ecs {

struct Entity {
    static constexpr std::uint32_t kInvalidIndex = std::numeric_limits<std::uint32_t>::max();
    std::uint32_t index = kInvalidIndex;
    std::uint32_t generation = 0;

    bool valid() const { return index != kInvalidIndex; }
    friend bool operator==(const Entity&, const Entity&) = default;
};
inline constexpr Entity kNullEntity{};

// Hands out entity indices, recycles them with a bumped generation.
class EntityPool {
public:
    Entity create() {
        if (!freeIndices_.empty()) {
            const std::uint32_t index = freeIndices_.back();
            freeIndices_.pop_back();
            return {index, generations_[index]};
        }
        generations_.push_back(0);
        return {static_cast<std::uint32_t>(generations_.size() - 1), 0};
    }
    void destroy(Entity e) {
        if (!alive(e)) return;
        ++generations_[e.index];
        freeIndices_.push_back(e.index);
    }
    bool alive(Entity e) const { return e.index < generations_.size() && generations_[e.index] == e.generation; }
    // One past the largest index ever handed out (size for per-entity arrays).
    std::uint32_t indexCapacity() const { return static_cast<std::uint32_t>(generations_.size()); }
    std::uint32_t aliveCount() const { return indexCapacity() - static_cast<std::uint32_t>(freeIndices_.size()); }

private:
    std::vector<std::uint32_t> generations_;
    std::vector<std::uint32_t> freeIndices_;
};

}  // namespace rtlab::ecs
