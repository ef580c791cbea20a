#pragma once
// The model's two-level acceleration structure for one frame: a BLAS per
// mesh and a TLAS over the instances, kept up to date from the ECS's
// FrameUpdate with the policy of tracer::AccelManager
// (docs/acceleration-structures.md):
//   mesh in rebuiltMeshes -> BLAS rebuild
//   mesh in refitMeshes   -> bottom-up BLAS refit (rebuild when its SAH cost
//                            exceeds bvh.refitRebuildThreshold x build cost)
//   otherwise             -> BLAS reused
//   any geometry change   -> TLAS rebuild over the instances' world boxes
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/rtcore_sim/bvh.hpp>
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <cstdint>
#include <memory>
#include <vector>

namespace rtlab::rtcore_sim {

// One TLAS instance; index = position in the snapshot (= Embree's instID).
struct ModelInstance {
    ecs::MeshId mesh = 0;
    mat4 worldFromObject{1.f};
    // The instance-transform step: inverse(worldFromObject), computed and
    // applied in double precision so that the object-space ray is the world
    // ray's correctly rounded image (docs/rtcore-model.md).
    glm::dmat4 objectFromWorld{1.0};
    std::uint8_t mask = 0xff;
    Aabb worldBounds;  // BLAS root box transformed to world space; empty for an empty BLAS
};

// What one update() did (names as in tracer::AccelUpdateStats).
struct ModelUpdateStats {
    std::uint32_t blasRebuilt = 0;  // includes blasRebuiltForQuality
    std::uint32_t blasRefit = 0;
    std::uint32_t blasReused = 0;
    std::uint32_t blasRebuiltForQuality = 0;  // refits turned into rebuilds by the SAH-cost policy
    std::uint32_t tlasBuilds = 0;
    std::uint32_t instancesMoved = 0;
    float worstRefitDegradation = 1.f;  // max over refit BLASes of SAH cost / cost at build
};

class ModelScene {
public:
    explicit ModelScene(BvhParams params = {});

    ModelUpdateStats update(const ecs::SceneSnapshot& scene);

    const BvhParams& params() const { return params_; }
    const Bvh& tlas() const { return tlas_; }
    const std::vector<ModelInstance>& instances() const { return instances_; }
    // For conservative TLAS box tests (tracer/conservative_bounds.hpp): the
    // largest magnitude any instance brings into world space (its world box,
    // its object coordinates scaled, its translation), times the worst
    // conditioning of an instance transform, and that conditioning.
    float tlasMagnitude() const { return tlasMagnitude_; }
    float tlasConditioning() const { return tlasConditioning_; }
    // The BLAS of `mesh`, or nullptr when it was never built.
    const Blas* blas(ecs::MeshId mesh) const { return mesh < blases_.size() ? blases_[mesh].get() : nullptr; }
    // One more than the largest MeshId that has (or had) a BLAS slot.
    std::size_t meshSlots() const { return blases_.size(); }
    // Incremented by every update(): anything derived from the BVHs (the
    // timing model's memory layout, its node cache) is stale once it changes.
    std::uint64_t generation() const { return generation_; }

private:
    void buildBlasOf(const ecs::MeshAsset& mesh, ecs::MeshId id);
    void rebuildTlas(const ecs::SceneSnapshot& scene, ModelUpdateStats& stats);

    BvhParams params_;
    tracer::EmbreeDevice device_;  // default thread configuration: builds run in their own one-thread arena
    BvhBuilder builder_;
    std::vector<std::unique_ptr<Blas>> blases_;  // indexed by MeshId
    std::vector<ModelInstance> instances_;
    Bvh tlas_;
    bool tlasBuilt_ = false;
    float tlasMagnitude_ = 0.f;
    float tlasConditioning_ = 1.f;
    std::uint64_t generation_ = 0;
};

}  // namespace rtlab::rtcore_sim
