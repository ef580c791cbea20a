#include <rtlab/study/ray_recorder.hpp>

#include <rtlab/tracer/embree_backend.hpp>

#include <stdexcept>

namespace rtlab::study {

RecordingBackend::RecordingBackend(tracer::TraversalBackend* inner) : inner_(inner) {
    if (!inner_) {
        ownedEmbree_ = std::make_unique<tracer::EmbreeBackend>();
        inner_ = ownedEmbree_.get();
    }
    rtcore_ = dynamic_cast<rtcore_sim::RtCoreBackend*>(inner_);
    if (rtcore_) rtcore_->keepCallVerdicts(true);
}

void RecordingBackend::beginLaunch(std::uint32_t threads, std::string_view label) {
    inner_->beginLaunch(threads, label);
    if (launchDepth_++ > 0) return;
    launchThreads_ = threads;
    launchRays_ = 0;
    lastOfThread_.assign(threads, RayLinkRecord::kNoParent);
    ++launches_;
}
void RecordingBackend::endLaunch() {
    if (launchDepth_ > 0) --launchDepth_;
    inner_->endLaunch();
}
void RecordingBackend::abortLaunch() {
    if (launchDepth_ > 0) --launchDepth_;
    inner_->abortLaunch();
}

RecordingBackend::~RecordingBackend() = default;

void RecordingBackend::beginFrame(const std::filesystem::path& path) {
    writer_ = std::make_unique<RayTraceWriter>(path);
    recordedRays_ = 0;
    launches_ = 0;
    hitGroupCount_ = 0;
    rayTypeCount_ = 1;
    anyHitShaders_ = false;
}

void RecordingBackend::endFrame(std::uint32_t frame, std::uint64_t sceneFingerprint, std::uint64_t instanceCount,
                                std::uint64_t uniqueTriangles) {
    if (!writer_) throw std::logic_error("RecordingBackend::endFrame without beginFrame");
    RayTraceInfo info;
    info.frame = frame;
    info.sceneFingerprint = sceneFingerprint;
    info.rayTypeCount = rayTypeCount_;
    info.hitGroupCount = hitGroupCount_;
    info.backend = inner_->name() == "rtcore" ? RecordedBackend::RtCore : RecordedBackend::Embree;
    info.anyHitShaders = anyHitShaders_;
    info.verdicts = rtcore_ != nullptr;
    info.instanceCount = instanceCount;
    info.uniqueTriangles = uniqueTriangles;
    writer_->finish(info);
    writer_.reset();
}

void RecordingBackend::trace(const tracer::TraceEngine& engine, const tracer::TraceArgs& args,
                             const tracer::RayDesc* rays, void* const* payloads, const bool* active, std::size_t count,
                             std::uint32_t depth, tracer::CommittedHit* out, tracer::TraceCounters& counters) {
    // A call outside any launch is a launch of its own (threads = its lanes), as on the model.
    const bool implicit = launchDepth_ == 0;
    const std::uint32_t threadBase = implicit ? 0 : tracer::currentTraceScope().thread;
    inner_->trace(engine, args, rays, payloads, active, count, depth, out, counters);
    if (!writer_) return;
    rayTypeCount_ = engine.rayTypeCount();
    hitGroupCount_ = static_cast<std::uint32_t>(engine.shaders().hitGroupCount());
    anyHitShaders_ = anyHitShaders_ || engine.shaders().anyHitGroupHasAnyHit();
    if (implicit) {
        launchThreads_ = static_cast<std::uint32_t>(count);
        launchRays_ = 0;
        lastOfThread_.assign(count, RayLinkRecord::kNoParent);
        ++launches_;
    }
    // Step: each recorded ray's parent (its thread's previous recorded ray);
    // the model's verdicts of its traced (valid) rays, 0 for invalid ones.
    parents_.clear();
    std::vector<std::uint32_t> counts;
    const rtcore_sim::RecordedVerdicts* verdicts = rtcore_ ? &rtcore_->callVerdicts() : nullptr;
    std::size_t traced = 0;
    for (std::size_t lane = 0; lane < count; ++lane) {
        if (!active[lane]) continue;
        const std::uint64_t thread = std::uint64_t(threadBase) + lane;
        if (thread >= lastOfThread_.size()) {
            lastOfThread_.resize(thread + 1, RayLinkRecord::kNoParent);
            launchThreads_ = static_cast<std::uint32_t>(thread + 1);
        }
        parents_.push_back(lastOfThread_[thread]);
        lastOfThread_[thread] = launchRays_++;
        if (verdicts) counts.push_back(tracer::isValidRay(rays[lane]) ? verdicts->counts[traced++] : 0);
    }
    BatchLaunch where;
    where.launch = launches_ - 1;
    where.launchThreads = launchThreads_;
    where.threadBase = threadBase;
    where.parents = parents_;
    where.verdictCounts = counts;
    if (verdicts) where.verdictWords = verdicts->words;
    writer_->append(args, depth, rays, active, out, count, where);
    recordedRays_ = writer_->rays();
}

}  // namespace rtlab::study
