#include <rtlab/study/replay.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/timer.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/tracer/embree_backend.hpp>

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

// Traces one batch on `backend` and compares with the recording.
void replayBatch(const tracer::TraceEngine& engine, tracer::TraversalBackend& backend,
                 const RayTraceFile::Batch& batch, std::uint64_t index, BatchOutcome& o) {
    // Step: the call as recorded: its lanes, the recorded rays on their lanes.
    const std::size_t n = batch.record->lanes;
    std::vector<tracer::RayDesc> rays(n);
    std::unique_ptr<bool[]> active(new bool[n]());
    std::vector<void*> payloads(n, nullptr);
    std::vector<tracer::CommittedHit> hits(n);
    for (const RayRecord& r : batch.rays) {
        rays[r.lane] = rayOf(r);
        active[r.lane] = true;
    }
    o.rays += batch.rays.size();
    const tracer::TraceArgs args = batch.args();
    backend.trace(engine, args, rays.data(), payloads.data(), active.get(), n, batch.record->depth, hits.data(),
                  o.counters);
    const bool hitOnly = (args.rayFlags & tracer::RayFlag::AcceptFirstHitAndEndSearch) != 0;
    for (const RayRecord& record : batch.rays) {
        const std::uint32_t i = record.lane;
        const tracer::CommittedHit recorded = hitOf(record);
        if (!rtcore_sim::sameHit(recorded, hits[i], hitOnly)) {
            ++o.differing;
            if (o.examples.size() < kExamples)
                o.examples.push_back(DifferingHit{index, i, args.rayContribution & 0xf, rays[i], recorded, hits[i]});
        } else if (recorded.hit && !hitOnly &&
                   (std::memcmp(&recorded.t, &hits[i].t, sizeof(float)) != 0 ||
                    std::memcmp(recorded.attributes.values.data(), hits[i].attributes.values.data(),
                                2 * sizeof(float)) != 0)) {
            ++o.notBitIdentical;
        }
    }
}

}  // namespace

void checkReplayable(const RayTraceFile& file, std::uint64_t fingerprint) {
    const RayTraceInfo info = file.info();
    if (info.sceneFingerprint != fingerprint) {
        std::ostringstream s;
        s << "scene fingerprint 0x" << std::hex << info.sceneFingerprint << " of the recording does not match 0x"
          << fingerprint << std::dec << " of the scene at frame " << info.frame
          << " (recorded from another scene, scene parameters or frame)";
        throw InputError(file.path().string(), s.str());
    }
    if (info.anyHitShaders)
        throw InputError(file.path().string(),
                         "recorded with any-hit shaders (alpha-masked materials); replay runs no shader, so record "
                         "with --effects that leave out alpha");
}

ReplayResult replayRays(const RayTraceFile& file, const tracer::AccelManager& accel,
                        tracer::TraversalBackend* backend) {
    const RayTraceInfo info = file.info();
    const NoShaderTable shaders(info.hitGroupCount);
    const tracer::TraceEngine engine(accel, shaders, info.rayTypeCount);
    const auto& batches = file.batches();
    std::vector<BatchOutcome> outcomes(batches.size());
    const Stopwatch clock;
    if (backend) {
        // Step: order-dependent back ends get the batches in recorded order.
        for (std::size_t b = 0; b < batches.size(); ++b) replayBatch(engine, *backend, batches[b], b, outcomes[b]);
    } else {
        // Step: Embree: batches in parallel, outcomes reduced in order below.
        tracer::EmbreeBackend embree;
        parallelForEach(batches.size(), [&](std::size_t b) { replayBatch(engine, embree, batches[b], b, outcomes[b]); });
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

}  // namespace rtlab::study
