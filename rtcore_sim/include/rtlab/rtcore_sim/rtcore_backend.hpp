#pragma once
// The RT-core model as a tracer::TraversalBackend: `Pipeline<Payload>(accel,
// desc, &backend)` traces every TraceRay through the cycle-counted RtCore.
// The DXR rules stay in the tracer's CandidateFilter: the model's triangle
// unit and procedural AABB tests hand their candidates to it through the
// ProgrammableSide, so any-hit and intersection shaders are the pipeline's
// real C++ callables (each one charged as a round trip).
//
//   per frame:  backend.update(snapshot)     // same FrameUpdate as AccelManager
//               backend.beginFrame()         // zeroes the model's statistics
//               ... pipeline dispatches ...
//               backend.statsJson()          // the stats tree of the frame
//
// One trace call is one RtCore::run batch (a 16x16 tile of dispatchCoherent,
// or one ray of traceRay), submitted in warps. The back end is
// order-dependent (a simulated clock), so the pipeline feeds it tiles in
// order on one thread and results are identical for any thread count.
//
// Verification (setVerify): every ray is traced a second time through
// Embree (TraceEngine::trace) and the two committed hits are compared; any-hit
// and intersection shaders then run twice per candidate, so they must not
// accumulate into the payload for verification to be meaningful (the
// built-in shaders do not).
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/tracer/candidate_filter.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim {

// What the model measured for one primary ray (recursion depth 1, ray type
// 0), in submission order (see RtCoreBackend::recordPrimaryRays).
struct PrimaryRayRecord {
    std::uint32_t cycles = 0;      // latency: submission -> result returned (SimRayResult::cycles)
    std::uint32_t slotCycles = 0;  // admission into a ray slot -> traversal finished
    std::uint32_t nodeVisits = 0;  // internal nodes visited, both levels
};

// One disagreement between the model and Embree found by verification.
struct HitMismatch {
    std::uint32_t rayType = 0;
    std::uint32_t depth = 0;
    tracer::RayDesc ray;
    tracer::CommittedHit model;
    tracer::CommittedHit embree;
};

struct VerifyStats {
    std::uint64_t rays = 0;  // rays traced by both back ends
    std::uint64_t mismatches =
        0;  // hits differ: hit/miss, instance, geometry, primitive, HitKind, record, or t beyond 1e-6 relative
    std::uint64_t notBitIdentical = 0;    // closest-hit rays that match but differ in some bit of t or the attributes
    std::uint64_t anyHitOnlyRays = 0;     // ACCEPT_FIRST_HIT_AND_END_SEARCH rays: only hit/miss compared
    double maxRelativeTDifference = 0.0;  // over rays whose ids agree
    std::vector<HitMismatch> examples;    // the first few mismatches
};

// Compares two committed hits the way verification does: both miss, or
// both hit the same instance, geometry and primitive with the same HitKind
// and hit-group record, and t within `relativeTolerance` (relative to the
// larger |t|). With `hitOnly` (rays that accept the first hit, whose
// committed hit is any hit) only hit/miss is compared.
bool sameHit(const tracer::CommittedHit& a, const tracer::CommittedHit& b, bool hitOnly,
             double relativeTolerance = 1e-6);

class RtCoreBackend final : public tracer::TraversalBackend {
public:
    // `config` is validated (InputError on bad cross-field values).
    explicit RtCoreBackend(const RtCoreConfig& config);
    ~RtCoreBackend() override;

    // Brings the model's BVHs up to date with the snapshot (refit, rebuild or
    // reuse per mesh, as AccelManager does with the same FrameUpdate).
    ModelUpdateStats update(const ecs::SceneSnapshot& scene);
    // Start of a frame: the model's statistics, the verification counts and
    // the primary-ray records are zeroed (the clock and the cache stay).
    void beginFrame();

    // Keep a PrimaryRayRecord for every ray traced at depth 1 with ray type
    // (RayContributionToHitGroupIndex) 0 (heatmaps).
    void recordPrimaryRays(bool on) { recordPrimary_ = on; }
    const std::vector<PrimaryRayRecord>& primaryRays() const { return primary_; }

    // Trace every ray through Embree as well and compare (VerifyStats).
    void setVerify(bool on) { verify_ = on; }
    const VerifyStats& verifyStats() const { return verifyStats_; }

    // Read these between dispatches (they are not locked against a running trace).
    // The model's stats tree for the frame (RtCore::statsJson, including
    // "config"), plus "backend": trace calls and rays that never reached the
    // model (invalid rays count as misses, as on Embree).
    nlohmann::json statsJson() const;

    const RtCoreConfig& config() const { return config_; }
    const ModelScene& model() const { return model_; }
    RtCore& core() { return *core_; }

    // tracer::TraversalBackend
    std::string_view name() const override { return "rtcore"; }
    bool orderDependent() const override { return true; }
    void trace(const tracer::TraceEngine& engine, const tracer::TraceArgs& args, const tracer::RayDesc* rays,
               void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
               tracer::CommittedHit* out, tracer::TraceCounters& counters) override;

private:
    void verifyBatch(const tracer::TraceEngine& engine, const tracer::TraceArgs& args, const tracer::RayDesc* rays,
                     void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
                     const tracer::CommittedHit* out);

    RtCoreConfig config_;
    ModelScene model_;
    std::unique_ptr<RtCore> core_;
    std::mutex mutex_;  // the core is one simulated machine: one trace call at a time

    bool recordPrimary_ = false;
    std::vector<PrimaryRayRecord> primary_;
    bool verify_ = false;
    VerifyStats verifyStats_;
    std::uint64_t traceCalls_ = 0;
    std::uint64_t invalidRays_ = 0;

    // Scratch reused across trace calls.
    std::vector<SimRay> simRays_;
    std::vector<SimRayResult> results_;
    std::vector<std::uint32_t> laneOf_;
    std::vector<tracer::LaneCommitState> lanes_;
};

}  // namespace rtlab::rtcore_sim
