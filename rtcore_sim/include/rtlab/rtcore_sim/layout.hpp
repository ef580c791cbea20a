#pragma once
// Byte layout of the model's acceleration structures in memory
// (docs/rtcore-model.md, "Memory layout"), so that the node cache sees real
// addresses:
//
//   internal node  16-byte header + width x (24-byte float AABB + 4-byte child reference)
//   TLAS leaf      8-byte header + 4 bytes per instance reference
//   BLAS leaf      8-byte header + 44 bytes per primitive slot
//                  (36 bytes: three float3 vertices, or an AABB padded to 36; 8 bytes: geometry and primitive ids)
//   instance       64-byte descriptor (3x4 float transform, BLAS address, mask, flags, id)
//
// Regions, each starting at a multiple of 4096 bytes, in this order: the
// TLAS, the instance table, then one region per mesh with a non-empty BLAS in
// MeshId order. A BVH region holds its nodes (array order, fixed size) and
// then its leaves (array order, variable size).
#include <rtlab/rtcore_sim/model_scene.hpp>

#include <cstdint>
#include <vector>

namespace rtlab::rtcore_sim {

inline constexpr std::uint32_t kNodeHeaderBytes = 16;
inline constexpr std::uint32_t kNodeChildBytes = 28;
inline constexpr std::uint32_t kLeafHeaderBytes = 8;
inline constexpr std::uint32_t kTlasRefBytes = 4;
inline constexpr std::uint32_t kBlasSlotBytes = 44;
inline constexpr std::uint32_t kInstanceBytes = 64;
inline constexpr std::uint64_t kRegionAlignment = 4096;

constexpr std::uint32_t nodeBytes(std::uint32_t width) { return kNodeHeaderBytes + kNodeChildBytes * width; }
constexpr std::uint32_t tlasLeafBytes(std::uint32_t refs) { return kLeafHeaderBytes + kTlasRefBytes * refs; }
constexpr std::uint32_t blasLeafBytes(std::uint32_t refs) { return kLeafHeaderBytes + kBlasSlotBytes * refs; }

// A contiguous byte range in the model's memory.
struct MemoryRange {
    std::uint64_t address = 0;
    std::uint32_t bytes = 0;
};

class MemoryLayout {
public:
    // Addresses for the scene's current BVHs.
    void build(const ModelScene& scene);

    MemoryRange tlasNode(std::uint32_t node) const {
        return {tlas_.nodeBase + std::uint64_t(node) * nodeBytes_, nodeBytes_};
    }
    MemoryRange tlasLeaf(const BvhLeaf& leaf, std::uint32_t leafIndex) const {
        return {
            tlas_.leafBase + std::uint64_t(kLeafHeaderBytes) * leafIndex + std::uint64_t(kTlasRefBytes) * leaf.firstRef,
            tlasLeafBytes(leaf.refCount)};
    }
    MemoryRange instance(std::uint32_t index) const {
        return {instanceBase_ + std::uint64_t(kInstanceBytes) * index, kInstanceBytes};
    }
    MemoryRange blasNode(std::uint32_t mesh, std::uint32_t node) const {
        return {blas_[mesh].nodeBase + std::uint64_t(node) * nodeBytes_, nodeBytes_};
    }
    MemoryRange blasLeaf(std::uint32_t mesh, const BvhLeaf& leaf, std::uint32_t leafIndex) const {
        return {blas_[mesh].leafBase + std::uint64_t(kLeafHeaderBytes) * leafIndex +
                    std::uint64_t(kBlasSlotBytes) * leaf.firstRef,
                blasLeafBytes(leaf.refCount)};
    }

    std::uint64_t tlasBase() const { return tlas_.nodeBase; }
    std::uint64_t instanceTableBase() const { return instanceBase_; }
    // The base of a region not laid out (a mesh without a non-empty BLAS).
    static constexpr std::uint64_t kNone = ~std::uint64_t(0);
    std::uint64_t totalBytes() const { return totalBytes_; }
    std::uint32_t nodeSize() const { return nodeBytes_; }

private:
    struct Region {
        std::uint64_t nodeBase = kNone;
        std::uint64_t leafBase = kNone;
    };
    std::uint32_t nodeBytes_ = 0;
    Region tlas_;
    std::uint64_t instanceBase_ = 0;
    std::vector<Region> blas_;  // by MeshId
    std::uint64_t totalBytes_ = 0;
};

}  // namespace rtlab::rtcore_sim
