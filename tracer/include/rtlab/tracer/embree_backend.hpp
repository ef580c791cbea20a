#pragma once
// The Embree back end (src/embree_backend.cpp): TraceEngine, TraceRay with
// DXR semantics on Embree (every candidate through the shared
// CandidateFilter, procedural primitives through intersection shaders,
// watertight triangle clusters as user geometry), which a Pipeline without a
// back end calls directly; and EmbreeBackend, the same traversal as an
// explicit TraversalBackend: a trace call's rays go through
// TraceEngine::trace8 in groups of 8 lanes (a last partial group is padded
// with inactive lanes) or TraceEngine::trace for a single ray, so the hits
// are exactly those of a pipeline without a back end. What EmbreeBackend is
// for: wrapping Embree like any other back end (the ray recorder of
// study/ray_recorder.hpp sees every call with its batch boundaries) and
// replaying recorded batches. Not order-dependent; thread-safe.
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/traversal_backend.hpp>

#include <cstdint>

namespace rtlab::tracer {

// Traversal with DXR semantics over an AccelManager's TLAS.
class TraceEngine {
public:
    TraceEngine(const AccelManager& accel, const ShaderTableView& shaders, std::uint32_t rayTypeCount);

    // One ray; runs any-hit and intersection shaders, not closest-hit/miss.
    CommittedHit trace(const TraceArgs& args, const RayDesc& ray, void* payload, std::uint32_t depth,
                       TraceCounters& counters) const;
    // Eight rays as one Embree packet (rtcIntersect8 / rtcOccluded8); lanes
    // with active[i] == false are left alone.
    // `coherence` is a hint to Embree (RayCoherence); the hits are the same.
    void trace8(const TraceArgs& args, const RayDesc* rays, void* const* payloads, const bool* active,
                std::uint32_t depth, CommittedHit* out, TraceCounters& counters,
                RayCoherence coherence = RayCoherence::Coherent) const;

    // The hit-group record for a hit; throws PipelineError when out of range.
    std::uint32_t hitGroupRecord(const TraceArgs& args, std::uint32_t instanceIndex,
                                 std::uint32_t geometryIndex) const {
        const InstanceFacts& facts = accel_.instanceFacts(instanceIndex);
        const std::uint64_t instanceContribution = facts.hitGroupOffset == ecs::MeshInstance::kAutomatic
                                                       ? std::uint64_t(facts.geometrySlotBase) * rayTypeCount_
                                                       : facts.hitGroupOffset;
        const std::uint64_t record =
            (args.rayContribution & 0xf) + std::uint64_t(args.multiplier & 0xf) * geometryIndex + instanceContribution;
        if (record >= hitGroupCount_) [[unlikely]]
            throwRecordOutOfRange(record, instanceIndex, geometryIndex);
        return static_cast<std::uint32_t>(record);
    }
    HitContext hitContext(const TraceArgs& args, const RayDesc& ray, const CommittedHit& hit,
                          std::uint32_t depth) const {
        HitContext hc;
        hc.worldRayOrigin = ray.origin;
        hc.worldRayDirection = ray.direction;
        hc.rayTMin = ray.tMin;
        hc.rayTCurrent = hit.t;
        hc.rayFlags = args.rayFlags;
        hc.instanceIndex = hit.instanceIndex;
        hc.instance = &accel_.instance(hit.instanceIndex);
        hc.instanceId = hc.instance->instanceId;
        hc.geometryIndex = hit.geometryIndex;
        hc.primitiveIndex = hit.primitiveIndex;
        hc.hitKind = hit.hitKind;
        hc.recursionDepth = depth;
        return hc;
    }

    const AccelManager& accel() const { return accel_; }
    const ShaderTableView& shaders() const { return shaders_; }
    std::uint32_t rayTypeCount() const { return rayTypeCount_; }

private:
    [[noreturn]] void throwRecordOutOfRange(std::uint64_t record, std::uint32_t instanceIndex,
                                            std::uint32_t geometryIndex) const;

    const AccelManager& accel_;
    const ShaderTableView& shaders_;
    std::uint32_t rayTypeCount_;
    std::size_t hitGroupCount_;  // the shader table is fixed for the engine's lifetime
};

class EmbreeBackend final : public TraversalBackend {
public:
    // `coherence`: the hint every packet of this back end gives Embree.
    explicit EmbreeBackend(RayCoherence coherence = RayCoherence::Coherent) : coherence_(coherence) {}
    std::string_view name() const override { return "embree"; }
    bool orderDependent() const override { return false; }
    void trace(const TraceEngine& engine, const TraceArgs& args, const RayDesc* rays, void* const* payloads,
               const bool* active, std::size_t count, std::uint32_t depth, CommittedHit* out,
               TraceCounters& counters) override;

private:
    RayCoherence coherence_;
};

}  // namespace rtlab::tracer
