#include <rtlab/study/ray_recorder.hpp>

#include <rtlab/tracer/embree_backend.hpp>

#include <stdexcept>

namespace rtlab::study {

RecordingBackend::RecordingBackend(tracer::TraversalBackend* inner) : inner_(inner) {
    if (!inner_) {
        ownedEmbree_ = std::make_unique<tracer::EmbreeBackend>();
        inner_ = ownedEmbree_.get();
    }
}

RecordingBackend::~RecordingBackend() = default;

void RecordingBackend::beginFrame(const std::filesystem::path& path) {
    writer_ = std::make_unique<RayTraceWriter>(path);
    recordedRays_ = 0;
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
    info.instanceCount = instanceCount;
    info.uniqueTriangles = uniqueTriangles;
    writer_->finish(info);
    writer_.reset();
}

void RecordingBackend::trace(const tracer::TraceEngine& engine, const tracer::TraceArgs& args,
                             const tracer::RayDesc* rays, void* const* payloads, const bool* active, std::size_t count,
                             std::uint32_t depth, tracer::CommittedHit* out, tracer::TraceCounters& counters) {
    inner_->trace(engine, args, rays, payloads, active, count, depth, out, counters);
    if (!writer_) return;
    rayTypeCount_ = engine.rayTypeCount();
    hitGroupCount_ = static_cast<std::uint32_t>(engine.shaders().hitGroupCount());
    anyHitShaders_ = anyHitShaders_ || engine.shaders().anyHitGroupHasAnyHit();
    writer_->append(args, depth, rays, active, out, count);
    recordedRays_ = writer_->rays();
}

}  // namespace rtlab::study
