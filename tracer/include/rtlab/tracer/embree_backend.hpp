#pragma once
// Embree as an explicit tracer::TraversalBackend: a trace call's rays go
// through TraceEngine::trace8 in groups of 8 lanes (a last partial group is
// padded with inactive lanes) or TraceEngine::trace for a single ray, so the
// hits are exactly those of a pipeline without a back end. What it is for:
// wrapping Embree like any other back end (the ray recorder of
// study/ray_recorder.hpp sees every call with its batch boundaries) and
// replaying recorded batches. Not order-dependent; thread-safe.
#include <rtlab/tracer/pipeline.hpp>

namespace rtlab::tracer {

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
