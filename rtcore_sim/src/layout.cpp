#include <rtlab/rtcore_sim/layout.hpp>

namespace rtlab::rtcore_sim {
namespace {

std::uint64_t alignUp(std::uint64_t v, std::uint64_t alignment) { return (v + alignment - 1) / alignment * alignment; }

std::uint64_t bvhBytes(const Bvh& bvh, std::uint32_t nodeSize, std::uint32_t slotBytes) {
    return std::uint64_t(bvh.nodes.size()) * nodeSize + std::uint64_t(kLeafHeaderBytes) * bvh.leaves.size() +
           std::uint64_t(slotBytes) * bvh.refs.size();
}

}  // namespace

void MemoryLayout::build(const ModelScene& scene) {
    nodeBytes_ = nodeBytes(scene.params().width);
    // Step: the TLAS at address 0.
    std::uint64_t next = 0;
    const Bvh& tlas = scene.tlas();
    tlas_.nodeBase = next;
    tlas_.leafBase = next + std::uint64_t(tlas.nodes.size()) * nodeBytes_;
    next = alignUp(next + bvhBytes(tlas, nodeBytes_, kTlasRefBytes), kRegionAlignment);
    // Step: the instance table.
    instanceBase_ = next;
    next = alignUp(next + std::uint64_t(kInstanceBytes) * scene.instances().size(), kRegionAlignment);
    // Step: one region per non-empty BLAS, in MeshId order.
    blas_.assign(scene.meshSlots(), Region{});
    for (std::uint32_t m = 0; m < scene.meshSlots(); ++m) {
        const Blas* blas = scene.blas(m);
        if (!blas || blas->bvh.empty()) continue;
        blas_[m].nodeBase = next;
        blas_[m].leafBase = next + std::uint64_t(blas->bvh.nodes.size()) * nodeBytes_;
        next = alignUp(next + bvhBytes(blas->bvh, nodeBytes_, kBlasSlotBytes), kRegionAlignment);
    }
    totalBytes_ = next;
}

}  // namespace rtlab::rtcore_sim
