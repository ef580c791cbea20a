#include <rtlab/study/replay.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/timer.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/tracer/embree_backend.hpp>

#include <algorithm>
#include <cstring>
#include <sstream>

namespace rtlab::study {
namespace {

// A shader table of `records` hit groups without any shader: traversal
// alone (every candidate the DXR rules let through is accepted).
class NoShaderTable final : public tracer::ShaderTableView {
public:
    explicit NoShaderTable(std::size_t records) : records_(records) {}
    std::size_t hitGroupCount() const override { return records_; }
    bool anyHitGroupHasAnyHit() const override { return false; }
    bool hasAnyHit(std::uint32_t) const override { return false; }
    tracer::AnyHitResult anyHit(std::uint32_t, const tracer::HitContext&, void*,
                                const tracer::HitAttributes&) const override {
        return tracer::AnyHitResult::Accept;
    }
    bool hasIntersection(std::uint32_t) const override { return false; }
    void intersection(std::uint32_t, const tracer::IntersectionContext&, void*) const override {}

private:
    std::size_t records_;
};

constexpr std::size_t kExamples = 8;

// What one batch's replay found.
struct BatchOutcome {
    tracer::TraceCounters counters;
    std::uint64_t rays = 0, differing = 0, notBitIdentical = 0;
    std::vector<DifferingHit> examples;
};

// Traces one batch on `backend` and compares with the recording. With
// `keepLanes` the call is rebuilt lane for lane (the model forms its warps
// from the call as submitted); otherwise the recorded rays are packed densely
// (Embree's hits do not depend on the lane a ray sits in, its packets do).
void replayBatch(const tracer::TraceEngine& engine, tracer::TraversalBackend& backend, const RayTraceFile::Batch& batch,
                 std::uint64_t index, bool keepLanes, BatchOutcome& o, bool verdictsReplayed = false) {
    const std::size_t n = keepLanes ? batch.record->lanes : batch.rays.size();
    std::vector<tracer::RayDesc> rays(n);
    std::unique_ptr<bool[]> active(new bool[n]());
    std::vector<void*> payloads(n, nullptr);
    std::vector<tracer::CommittedHit> hits(n);
    for (std::size_t k = 0; k < batch.rays.size(); ++k) {
        const std::size_t lane = keepLanes ? batch.rays[k].lane : k;
        rays[lane] = rayOf(batch.rays[k]);
        active[lane] = true;
    }
    o.rays += batch.rays.size();
    const tracer::TraceArgs args = batch.args();
    backend.trace(engine, args, rays.data(), payloads.data(), active.get(), n, batch.record->depth, hits.data(),
                  o.counters);
    const bool hitOnly = (args.rayFlags & tracer::RayFlag::AcceptFirstHitAndEndSearch) != 0;
    for (std::size_t k = 0; k < batch.rays.size(); ++k) {
        const RayRecord& record = batch.rays[k];
        const std::uint32_t i = keepLanes ? record.lane : std::uint32_t(k);
        const tracer::CommittedHit recorded = hitOf(record);
        if (verdictsReplayed && hits[i].hit) {
            // No shader ran to say HitKind and record (RtCoreBackend::replayVerdicts): the recording's.
            hits[i].hitKind = recorded.hitKind;
            hits[i].hitGroupRecord = recorded.hitGroupRecord;
        }
        if (!rtcore_sim::sameHit(recorded, hits[i], hitOnly)) {
            ++o.differing;
            if (o.examples.size() < kExamples)
                o.examples.push_back(
                    DifferingHit{index, record.lane, args.rayContribution & 0xf, rays[i], recorded, hits[i]});
        } else if (recorded.hit && !hitOnly &&
                   (std::memcmp(&recorded.t, &hits[i].t, sizeof(float)) != 0 ||
                    std::memcmp(recorded.attributes.values.data(), hits[i].attributes.values.data(),
                                2 * sizeof(float)) != 0)) {
            ++o.notBitIdentical;
        }
    }
}

// The recorded verdicts of the rays the model traces (valid ones), in lane
// order, for the model's next trace call. `counts` is scratch.
void giveVerdicts(rtcore_sim::RtCoreBackend& model, const RayTraceFile::Batch& batch,
                  std::vector<std::uint32_t>& counts) {
    counts.clear();
    for (std::size_t k = 0; k < batch.rays.size(); ++k)
        if (tracer::isValidRay(rayOf(batch.rays[k]))) counts.push_back(batch.links[k].verdicts);
        else if (batch.links[k].verdicts != 0)
            throw InputError("ray-trace file", "an invalid ray carries verdicts (corrupt recording)");
    model.replayVerdicts(rtcore_sim::RecordedVerdicts{counts, batch.verdicts});
}

// Launch mode on the model: the recorded launches in order, each call with
// its threads and (when recorded) its verdicts, every launch simulated at its end.
void replayLaunches(const tracer::TraceEngine& engine, rtcore_sim::RtCoreBackend& model,
                    const std::vector<RayTraceFile::Batch>& batches, bool verdicts,
                    std::vector<BatchOutcome>& outcomes) {
    std::vector<std::uint32_t> counts;
    struct RestoreThread {
        std::uint32_t saved = tracer::currentTraceScope().thread;
        ~RestoreThread() { tracer::currentTraceScope().thread = saved; }
    } restore;
    for (std::size_t b = 0; b < batches.size();) {
        // Step: the launch's batches and its threads.
        const std::uint32_t launch = batches[b].launch->launch;
        std::size_t end = b;
        std::uint32_t threads = 0;
        while (end < batches.size() && batches[end].launch->launch == launch)
            threads = std::max(threads, batches[end++].launch->launchThreads);
        tracer::LaunchScope scope(&model, threads);
        for (; b < end; ++b) {
            const RayTraceFile::Batch& batch = batches[b];
            tracer::currentTraceScope().thread = batch.launch->threadBase;
            if (verdicts) giveVerdicts(model, batch, counts);
            replayBatch(engine, model, batch, b, true, outcomes[b], verdicts);
        }
        scope.end();
    }
}

}  // namespace

void checkReplayable(const RayTraceFile& file, std::uint64_t fingerprint, const tracer::TraversalBackend* backend) {
    const RayTraceInfo info = file.info();
    if (info.sceneFingerprint != fingerprint) {
        std::ostringstream s;
        s << "scene fingerprint 0x" << std::hex << info.sceneFingerprint << " of the recording does not match 0x"
          << fingerprint << std::dec << " of the scene at frame " << info.frame
          << " (recorded from another scene, scene parameters or frame)";
        throw InputError(file.path().string(), s.str());
    }
    const auto* model = dynamic_cast<const rtcore_sim::RtCoreBackend*>(backend);
    const bool launchMode = model && model->launchMode();
    if (launchMode && info.version < 2)
        throw InputError(file.path().string(),
                         "recorded before launches (ray-trace format version 1: no launches, threads or verdicts); "
                         "replay it with --rtcore-set gpu.launch=tile, or record it again with this rtlab");
    if (info.anyHitShaders && !(model && info.verdicts))
        throw InputError(file.path().string(),
                         "recorded with any-hit shaders (alpha-masked materials) and replay runs no shader: only a "
                         "recording made on --backend rtcore carries every any-hit verdict, and only --backend "
                         "rtcore replays them; or record with --effects that leave out alpha");
}

namespace {

ReplayResult replayAll(const RayTraceFile& file, const tracer::AccelManager& accel, tracer::TraversalBackend* backend,
                       std::uint32_t rayTypeMask) {
    const RayTraceInfo info = file.info();
    const NoShaderTable shaders(info.hitGroupCount);
    const tracer::TraceEngine engine(accel, shaders, info.rayTypeCount);
    std::vector<RayTraceFile::Batch> batches;
    for (const RayTraceFile::Batch& b : file.batches())
        if (rayTypeMask >> (b.record->rayContribution & 0xf) & 1) batches.push_back(b);
    std::vector<BatchOutcome> outcomes(batches.size());
    const Stopwatch clock;
    auto* model = dynamic_cast<rtcore_sim::RtCoreBackend*>(backend);
    if (model && model->launchMode()) {
        // Step: the model in launch mode gets the recorded launches.
        replayLaunches(engine, *model, batches, info.verdicts, outcomes);
    } else if (backend) {
        // Step: order-dependent back ends get the batches in recorded order
        // (the model in tile mode with the recorded verdicts, when there are some).
        const bool verdicts = model && info.verdicts;
        std::vector<std::uint32_t> counts;
        for (std::size_t b = 0; b < batches.size(); ++b) {
            if (verdicts) giveVerdicts(*model, batches[b], counts);
            replayBatch(engine, *backend, batches[b], b, true, outcomes[b], verdicts);
        }
    } else {
        // Step: Embree: batches in parallel, outcomes reduced in order below.
        // Ray type 0 (rtlab's primary rays) as coherent packets, the rest
        // (shadow, bounce, AO: scattered) as incoherent ones.
        tracer::EmbreeBackend coherent(tracer::RayCoherence::Coherent), incoherent(tracer::RayCoherence::Incoherent);
        parallelForEach(batches.size(), [&](std::size_t b) {
            tracer::EmbreeBackend& embree = (batches[b].record->rayContribution & 0xf) == 0 ? coherent : incoherent;
            replayBatch(engine, embree, batches[b], b, false, outcomes[b]);
        });
    }
    ReplayResult r;
    r.milliseconds = clock.elapsedMs();
    r.batches = batches.size();
    for (const BatchOutcome& o : outcomes) {
        r.counters.add(o.counters);
        r.rays += o.rays;
        r.differingHits += o.differing;
        r.notBitIdentical += o.notBitIdentical;
        for (const DifferingHit& d : o.examples)
            if (r.examples.size() < kExamples) r.examples.push_back(d);
    }
    return r;
}

}  // namespace

ReplayResult replayRays(const RayTraceFile& file, const tracer::AccelManager& accel, tracer::TraversalBackend* backend,
                        std::uint32_t rayTypeMask) {
    try {
        return replayAll(file, accel, backend, rayTypeMask);
    } catch (const tracer::PipelineError& e) {
        // E.g. a hit whose hit-group record lies beyond the recorded table: the file's fault.
        throw InputError("recorded rays", std::string(e.what()) + " (the recording does not match this scene)");
    }
}

}  // namespace rtlab::study
