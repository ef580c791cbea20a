#pragma once
// Retained acceleration structures over Embree: one BLAS per mesh asset,
// instanced into a TLAS. Work is driven only by the frame's FrameUpdate:
//   moved instance  -> TLAS update only
//   deformed mesh   -> BLAS refit (same topology)
//   new/topology    -> BLAS rebuild
//   untouched       -> no work
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/tracer/watertight_triangle.hpp>

#include <embree3/rtcore.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

namespace rtlab::tracer {

struct AccelOptions {
    bool robust = true;  // RTC_SCENE_FLAG_ROBUST: watertight-leaning traversal and intersection
    int threads = 0;     // Embree build threads (0 = all)
    // Refit quality policy: a refit BLAS keeps its build-time topology, so its
    // quality decays as vertices move. Every refitQualityCheckInterval refits
    // the SAH-style cost of the refit grouping is compared with the grouping a
    // rebuild would make now; above this ratio the BLAS is rebuilt instead
    // (docs/acceleration-structures.md). <= 0 disables the policy.
    float refitRebuildThreshold = 1.5f;
    std::uint32_t refitQualityCheckInterval = 8;
    // Watertight triangles: Embree 3.13.5's robust triangle test leaks rays
    // through shared vertices (docs/acceleration-structures.md). With this on,
    // triangles are grouped into clusters of up to 4 (Morton order of their
    // centroids), each cluster one Embree user primitive intersected by the
    // single-precision Woop-Benthin-Wald test (watertight_triangle.hpp), and
    // every cluster box is padded conservatively for the magnitude of its
    // coordinates and of the ray origins (conservative_bounds.hpp), because
    // Embree's user-geometry and instance BVHs use the non-robust box test.
    bool watertight = true;
    // Largest |coordinate| of any ray origin the caller will trace from,
    // beyond the scene's geometry and camera (which are always included).
    // Raygen shaders that start rays far outside the scene set it.
    float rayOriginBound = 0.f;
};

// The user data of a watertight triangle geometry (read by its callbacks):
// clusters of up to kClusterTriangles triangles, one Embree user primitive each.
struct WatertightTriangles {
    std::vector<TriangleCluster> clusters;
    float padding = 0.f;  // absolute enlargement of every cluster box (object space)
};

// Per-geometry facts the pipeline needs during traversal.
struct GeometryInfo {
    bool opaque = true;       // D3D12_RAYTRACING_GEOMETRY_FLAG_OPAQUE (material is not alpha-masked/blended)
    bool procedural = false;  // AABBs + intersection shader
};

// What one update() did.
struct AccelUpdateStats {
    std::uint32_t blasRebuilt = 0;
    std::uint32_t blasRefit = 0;
    std::uint32_t blasReused = 0;
    std::uint32_t tlasBuilds = 0;   // full TLAS rebuilds (instance set changed)
    std::uint32_t tlasUpdates = 0;  // TLAS recommits for moved instances only
    std::uint32_t instancesMoved = 0;
    std::uint32_t blasRebuiltForQuality = 0;  // refits turned into rebuilds by the quality policy
    std::uint32_t blasRepadded = 0;  // untouched BLASes whose cluster boxes grew because ray origins grew in magnitude
    float worstRefitDegradation = 1.f;  // max over BLASes checked this frame of refit cost / rebuild cost
    double buildMs = 0.0;
};

// Facts about one TLAS instance that traversal needs per hit.
struct InstanceFacts {
    mat3 normalFromObject{1.f};       // inverse transpose of worldFromObject's 3x3
    glm::dmat4 objectFromWorld{1.0};  // objectFromWorldOf(worldFromObject) (instance_transform.hpp)
    bool mayBeNonOpaque = false;      // some geometry is non-opaque after instance flags
    bool hasProcedural = false;
    bool frontCounterClockwise = false;  // InstanceFlag::TriangleFrontCounterClockwise
    std::uint32_t geometrySlotBase = 0;  // geometrySlotBase(instance's mesh)
    std::uint32_t hitGroupOffset = 0;    // the instance's InstanceContributionToHitGroupIndex (or kAutomatic)
};

// Owns the Embree device.
class EmbreeDevice {
public:
    explicit EmbreeDevice(int threads = 0);
    ~EmbreeDevice();
    EmbreeDevice(const EmbreeDevice&) = delete;
    EmbreeDevice& operator=(const EmbreeDevice&) = delete;
    RTCDevice get() const { return device_; }
    // Bytes the device holds now (Embree's memory monitor: BVHs, scenes,
    // geometry buffers). Embree's builders allocate per build thread, so
    // the figure depends on the thread count: a measurement, not a
    // deterministic statistic.
    std::int64_t bytesInUse() const { return bytes_.load(std::memory_order_relaxed); }

private:
    RTCDevice device_ = nullptr;
    std::atomic<std::int64_t> bytes_{0};
};

class AccelManager {
public:
    explicit AccelManager(AccelOptions options = {});
    ~AccelManager();
    AccelManager(const AccelManager&) = delete;
    AccelManager& operator=(const AccelManager&) = delete;

    // Brings the BLASes and the TLAS up to date with `scene`.
    AccelUpdateStats update(const ecs::SceneSnapshot& scene);

    RTCScene tlas() const { return tlas_; }
    RTCDevice device() const { return device_.get(); }
    // Memory of the acceleration structures: what Embree holds
    // (EmbreeDevice::bytesInUse, thread-count dependent) and rtlab's own
    // watertight triangle clusters (deterministic).
    std::int64_t embreeBytes() const { return device_.bytesInUse(); }
    std::uint64_t clusterBytes() const;
    // TLAS instance id (Embree instID) -> the snapshot instance it came from.
    const ecs::InstanceSnapshot& instance(std::uint32_t instId) const { return instances_.at(instId); }
    std::size_t instanceCount() const { return instances_.size(); }
    const GeometryInfo& geometryInfo(ecs::MeshId mesh, std::uint32_t geometryIndex) const;
    const InstanceFacts& instanceFacts(std::uint32_t instId) const { return instanceFacts_[instId]; }
    // Every instance is opaque (after instance flags) / some instance has
    // procedural geometry. Traversal uses them to skip per-candidate work.
    bool allOpaque() const { return allOpaque_; }
    const AccelOptions& options() const { return options_; }
    bool anyProcedural() const { return anyProcedural_; }
    std::uint32_t geometryCount(ecs::MeshId mesh) const;
    // Shader-table slot of geometry 0 of `mesh`: meshes are laid out in id
    // order, one slot per geometry (the automatic instance contribution is
    // slot * ray-type count).
    std::uint32_t geometrySlotBase(ecs::MeshId mesh) const { return slotBase_.at(mesh); }
    std::uint32_t geometrySlotCount() const { return slotCount_; }

private:
    struct Blas;
    RTCSceneFlags sceneFlags() const;
    void updateConservativePadding(const ecs::SceneSnapshot& scene, const std::vector<std::uint8_t>& changed);
    float requiredPadding(ecs::MeshId mesh) const;
    void attachUserGeometry(Blas& blas, std::size_t primitives, void* userData, RTCBuildQuality quality,
                            RTCBoundsFunction bounds, RTCIntersectFunctionN intersect, RTCOccludedFunctionN occluded);
    void buildBlas(const ecs::MeshAsset& mesh, ecs::MeshId id, const std::vector<ecs::Material>& materials);
    void refitBlas(const ecs::MeshAsset& mesh, ecs::MeshId id);
    void rebuildTlas(const ecs::SceneSnapshot& scene);

    AccelOptions options_;
    EmbreeDevice device_;
    std::vector<std::unique_ptr<Blas>> blases_;  // indexed by MeshId
    RTCScene tlas_ = nullptr;
    std::vector<ecs::InstanceSnapshot> instances_;
    std::vector<std::uint32_t> instIdByEntityIndex_;
    void refreshInstanceFacts();
    std::vector<InstanceFacts> instanceFacts_;
    bool allOpaque_ = true;
    bool anyProcedural_ = false;
    // Conservative padding (conservative_bounds.hpp): per mesh the largest
    // |object coordinate|, and the padding its clusters need this frame.
    std::vector<float> objectMagnitude_;
    std::vector<float> neededPadding_;
    std::vector<std::uint32_t> slotBase_;
    std::uint32_t slotCount_ = 0;
};

inline void storeEmbreeBounds(RTCBounds* out, const Aabb& box) {
    out->lower_x = box.lo.x;
    out->lower_y = box.lo.y;
    out->lower_z = box.lo.z;
    out->upper_x = box.hi.x;
    out->upper_y = box.hi.y;
    out->upper_z = box.hi.z;
}

// Embree callbacks for procedural geometry, implemented by the trace engine
// (they call the pipeline's intersection shaders).
void proceduralBoundsCallback(const RTCBoundsFunctionArguments* args);
void proceduralIntersectCallback(const RTCIntersectFunctionNArguments* args);
void proceduralOccludedCallback(const RTCOccludedFunctionNArguments* args);
void watertightBoundsCallback(const RTCBoundsFunctionArguments* args);
void watertightIntersectCallback(const RTCIntersectFunctionNArguments* args);
void watertightOccludedCallback(const RTCOccludedFunctionNArguments* args);

}  // namespace rtlab::tracer
