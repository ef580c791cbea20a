#pragma once
// `rtlab render --record-rays DIR`: a traversal back end that forwards every
// trace call to the real one (Embree or the RT-core model) and appends the
// call, its rays and their committed hits to the frame's ray-trace file
// (ray_trace_file.hpp), with its launch, threads and parents (it follows the
// launches it forwards; a call outside any launch is a launch of its own)
// and, on the RT-core model, its candidates' verdicts. It is order-dependent, so the pipeline feeds it
// tiles in order on one thread: the file is the same for any thread count.
// On Embree the rays then go through tracer::EmbreeBackend (one batch per
// tile instead of packets per thread): the hits, and so the images, are
// the same as without recording.
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/study/ray_trace_file.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <memory>
#include <vector>

namespace rtlab::study {

class RecordingBackend final : public tracer::TraversalBackend {
public:
    // `inner` (not owned) traces; nullptr = Embree (tracer::EmbreeBackend).
    explicit RecordingBackend(tracer::TraversalBackend* inner);
    ~RecordingBackend() override;

    // Starts the frame's file at `path` (written to path.tmp until endFrame).
    void beginFrame(const std::filesystem::path& path);
    // Finishes and renames the frame's file; the shader-table facts come from
    // the last trace call (a frame without trace calls records 0 hit groups).
    void endFrame(std::uint32_t frame, std::uint64_t sceneFingerprint, std::uint64_t instanceCount,
                  std::uint64_t uniqueTriangles);
    // Rays recorded in the current (or last) frame.
    std::uint64_t recordedRays() const { return recordedRays_; }

    std::string_view name() const override { return inner_->name(); }
    bool orderDependent() const override { return true; }
    void beginLaunch(std::uint32_t threads, std::string_view label) override;
    void endLaunch() override;
    void abortLaunch() override;
    void trace(const tracer::TraceEngine& engine, const tracer::TraceArgs& args, const tracer::RayDesc* rays,
               void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
               tracer::CommittedHit* out, tracer::TraceCounters& counters) override;

private:
    std::unique_ptr<tracer::TraversalBackend> ownedEmbree_;
    tracer::TraversalBackend* inner_ = nullptr;
    std::unique_ptr<RayTraceWriter> writer_;
    std::uint64_t recordedRays_ = 0;
    std::uint32_t rayTypeCount_ = 1, hitGroupCount_ = 0;
    bool anyHitShaders_ = false;
    rtcore_sim::RtCoreBackend* rtcore_ = nullptr;  // inner, when it is the model (verdicts)
    // The open launch.
    std::uint32_t launchDepth_ = 0, launches_ = 0, launchThreads_ = 0;
    std::uint32_t launchRays_ = 0;             // rays recorded in it so far
    std::vector<std::uint32_t> lastOfThread_;  // per thread: its latest recorded ray
    std::vector<std::uint32_t> parents_;       // scratch
};

}  // namespace rtlab::study
