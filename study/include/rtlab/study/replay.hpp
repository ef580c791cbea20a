#pragma once
// `rtlab replay`: the recorded rays of a frame traced again, without shading
// (no closest-hit, miss or any-hit shader runs), on Embree or on the RT-core
// model, batch by batch as they were recorded (on the model in launch mode:
// launch by launch, the recorded any-hit / intersection verdicts replayed),
// and every committed hit compared with the recorded one. On the model, the same batches in the same
// order give the render's cycle count and stats exactly (from the same model
// state: replay the frames from frame 0 in order, as rtlab replay does).
#include <rtlab/study/ray_trace_file.hpp>
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <cstdint>
#include <vector>

namespace rtlab::study {

// A replayed hit that differs from the recorded one.
struct DifferingHit {
    std::uint64_t batch = 0;
    std::uint32_t lane = 0;
    std::uint32_t rayType = 0;
    tracer::RayDesc ray;
    tracer::CommittedHit recorded, replayed;
};

struct ReplayResult {
    std::uint64_t batches = 0;
    std::uint64_t rays = 0;              // active lanes traced
    tracer::TraceCounters counters;      // per ray type, as the back end counted them
    std::uint64_t differingHits = 0;     // hit/miss, ids, HitKind, record, or t beyond 1e-6 relative
    std::uint64_t notBitIdentical = 0;   // same hit, but some bit of t or the barycentrics differs
    std::vector<DifferingHit> examples;  // the first few differing hits
    double milliseconds = 0.0;           // wall time of the tracing alone
};

// Throws InputError when the file cannot be replayed on this scene and back
// end (nullptr = Embree): its fingerprint is not `sceneFingerprint`; it is
// a version 1 file (no launches) and the back end is the model in launch
// mode; or its rays ran any-hit shaders (alpha-masked materials) and their
// verdicts cannot be replayed (only a recording made on the model carries
// them, and only the model replays them).
void checkReplayable(const RayTraceFile& file, std::uint64_t sceneFingerprint, const tracer::TraversalBackend* backend);

// Throws InputError("recorded rays", ...) when a batch cannot be traced on
// this scene (a hit-group record beyond the recorded table) or its recorded
// verdicts do not fit. Traces every batch of `file` on `backend` in recorded order (nullptr =
// Embree through TraceEngine::trace8, batches spread over threads; the
// results do not depend on the thread count). Only batches whose ray type
// (RayContributionToHitGroupIndex & 0xf) has its bit in `rayTypeMask`.
ReplayResult replayRays(const RayTraceFile& file, const tracer::AccelManager& accel, tracer::TraversalBackend* backend,
                        std::uint32_t rayTypeMask = 0xffff);

}  // namespace rtlab::study
