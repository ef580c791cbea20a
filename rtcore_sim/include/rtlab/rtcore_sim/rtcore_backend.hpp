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
// gpu.launch = launch (the default; docs/rtcore-model.md, "Launches"): the
// trace calls of one launch (a pass of the renderer, or one dispatch) are
// answered at once by the functional traversal (the model's own, so the hits
// are the model's), their any-hit / intersection verdicts logged; at
// endLaunch the timing model simulates the whole launch from that log
// (RtCore::runLaunch), the verdicts replayed in order. The calls of a
// launch may run on several host threads at once: the log's order does not
// matter (the model orders a launch's rays by thread, a thread's in the
// order it traced them), so in launch mode the back end is not
// order-dependent (unless verifying or recording, whose records follow the
// call order). gpu.launch = tile: every trace call is one RtCore::run batch
// (a 16x16 tile of dispatchCoherent, or one ray of traceRay), simulated
// before it returns; the back end is order-dependent (a simulated clock),
// so the pipeline feeds it tiles in order on one thread. Either way results
// are identical for any thread count.
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
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace rtlab::rtcore_sim {

// What the model measured for one primary ray (recursion depth 1, ray type
// 0), in submission order; in launch mode, each launch's in thread order
// (see RtCoreBackend::recordPrimaryRays).
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

// A (valid) pipeline ray as the model traces it: its TraceRay arguments' mask,
// ray type (RayContributionToHitGroupIndex & 0xf) and skip flags.
SimRay simRayOf(const tracer::RayDesc& ray, const tracer::TraceArgs& args);

// A launch as the timing model simulates it (gpu.launch = launch): every
// ray its threads traced, in trace order (so a ray's parent is the previous
// ray of its thread), with the verdicts of its candidates. Verdict words per candidate: bit 0 commit, bit 1 end search,
// bit 2 a shader ran, bit 3 procedural (then one more word: the committed
// t's bits).
struct LaunchLog {
    static constexpr std::uint32_t kCommit = 1, kEndSearch = 2, kShaderRan = 4, kProcedural = 8;
    std::uint32_t threads = 0;
    std::vector<SimRay> rays;
    std::vector<std::uint32_t> thread;      // per ray
    std::vector<std::uint64_t> verdictEnd;  // per ray: end of its words (its start is the previous ray's end)
    std::vector<std::uint32_t> verdicts;    // the words
    std::uint64_t verdictBegin(std::size_t ray) const { return ray == 0 ? 0 : verdictEnd[ray - 1]; }
    void clear();
};

// Verdicts of one trace call from a recording (rtlab replay): per traced ray
// of the call, in lane order, its number of words, and the words.
struct RecordedVerdicts {
    std::span<const std::uint32_t> counts;
    std::span<const std::uint32_t> words;
};

// What one launch cost (the frame's stats tree's "launches"): its cycles,
// and per kind of resource the utilization of the busiest one of that kind
// over the launch (RtCore::resourceUse), the busiest of all named.
struct LaunchRecord {
    std::string label;  // the pass (renderer), "dispatch" or "trace call"; not in statsJson (a replay has no passes)
    std::uint64_t rays = 0, threads = 0, cycles = 0;
    std::vector<std::pair<std::string, double>> busiestByKind;  // kind -> utilization of its busiest instance
    std::string busiest;                                        // e.g. "raySlots of core 3"
    double busiestUtilization = 0.0;
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

    // The next trace call's candidates take these verdicts instead of the
    // shaders' (rtlab replay of a recording; both modes). The hits it
    // returns then carry the model's t, ids and barycentrics; HitKind and
    // record are 0 (no shader ran to say them).
    void replayVerdicts(const RecordedVerdicts& verdicts) {
        replay_ = verdicts;
        replaying_ = true;
    }
    // For a recording: keep the verdicts of each trace call's traced rays
    // (valid active lanes, in lane order) until the next call (both modes).
    void keepCallVerdicts(bool on) { keepCallVerdicts_ = on; }
    const RecordedVerdicts& callVerdicts() const { return callVerdicts_; }
    bool launchMode() const { return config_.gpu.launch == LaunchMode::Launch; }
    const std::vector<LaunchRecord>& launches() const { return launches_; }

    // tracer::TraversalBackend
    std::string_view name() const override { return "rtcore"; }
    bool orderDependent() const override { return !launchMode() || verify_ || keepCallVerdicts_; }
    void trace(const tracer::TraceEngine& engine, const tracer::TraceArgs& args, const tracer::RayDesc* rays,
               void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
               tracer::CommittedHit* out, tracer::TraceCounters& counters) override;
    void beginLaunch(std::uint32_t threads, std::string_view label) override;
    void endLaunch() override;
    void abortLaunch() override;

private:
    void traceFunctional(const tracer::TraceEngine& engine, const tracer::TraceArgs& args, const tracer::RayDesc* rays,
                         void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
                         tracer::CommittedHit* out, tracer::TraceCounters& counters);
    void traceConcurrently(const tracer::TraceEngine& engine, const tracer::TraceArgs& args,
                           const tracer::RayDesc* rays, void* const* payloads, const bool* active, std::size_t count,
                           std::uint32_t depth, tracer::CommittedHit* out, tracer::TraceCounters& counters);
    void growLaunchThreads(const bool* active, std::size_t count, std::uint32_t base);
    void flushLaunchPrimary(bool simulated);
    LaunchRecord launchRecord(const LaunchLog& log, std::uint64_t cycles, const std::vector<ResourceUse>& before,
                              const std::vector<ResourceUse>& after) const;
    void beginLaunchLocked(std::uint32_t threads, std::string_view label);
    void endLaunchLocked();
    void abortLaunchLocked();
    static void finishCall(const tracer::CandidateFilter& filter, const bool* active, std::size_t count, bool replaying,
                           std::span<const std::uint32_t> laneOf, std::span<const SimRayResult> results,
                           tracer::CommittedHit* out);
    void recordPrimary(const tracer::TraceArgs& args, std::uint32_t depth, const bool* active, std::size_t count,
                       std::span<const std::uint32_t> laneOf, std::size_t first, std::uint32_t base);
    void verifyBatch(const tracer::TraceEngine& engine, const tracer::TraceArgs& args, const tracer::RayDesc* rays,
                     void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
                     const tracer::CommittedHit* out);

    RtCoreConfig config_;
    ModelScene model_;
    std::unique_ptr<RtCore> core_;
    // The core is one simulated machine: one trace call at a time, except
    // the calls of an open launch (traceConcurrently), which take it only to
    // append to the launch's log.
    std::mutex mutex_;

    bool recordPrimary_ = false;
    std::vector<PrimaryRayRecord> primary_;
    bool verify_ = false;
    VerifyStats verifyStats_;
    std::uint64_t traceCalls_ = 0;
    std::uint64_t invalidRays_ = 0;

    LaunchLog launch_;
    std::uint32_t launchDepth_ = 0;
    bool launchFailed_ = false;  // a scope was left by an exception: the launch is dropped, not simulated
    std::string launchLabel_;
    std::size_t lastCallFirst_ = 0;
    // Launch mode: the launch's primary rays (thread, ray of the launch's log
    // or kNoRay for an invalid ray), appended to primary_ in thread order when
    // the launch is simulated.
    struct LaunchPrimary {
        std::uint32_t thread;
        std::size_t ray;
    };
    static constexpr std::size_t kNoRay = ~std::size_t(0);
    std::vector<LaunchPrimary> launchPrimary_;
    std::vector<LaunchRecord> launches_;
    RecordedVerdicts replay_;
    bool replaying_ = false;
    bool keepCallVerdicts_ = false;
    std::vector<std::uint32_t> callCounts_, callWords_;
    std::vector<std::vector<std::uint32_t>> tileVerdicts_;
    RecordedVerdicts callVerdicts_;

    // Scratch reused across trace calls.
    std::vector<SimRay> simRays_;
    std::vector<SimRayResult> results_;
    std::vector<std::uint32_t> laneOf_;
    std::vector<tracer::LaneCommitState> lanes_;
};

}  // namespace rtlab::rtcore_sim
