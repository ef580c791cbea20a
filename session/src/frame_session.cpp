// The frame driver (frame_session.hpp).
#include <rtlab/session/frame_session.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/timer.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <optional>
#include <thread>

#include <unistd.h>
#include <cstdlib>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace rtlab::session {

FrameSession::FrameSession(FrameOptions options, Stages stages, tracer::AccelOptions accelBase)
    : options_(std::move(options)), stages_(stages), threadLimit_(options_.threads) {
    // Step: the options, checked before anything is loaded (in the order the
    // command line has always reported them).
    options_.validate();
    planOptions_ = options_.planOptions();
    if (stages_ == Stages::Render && options_.denoises())
        denoiser_ = std::make_unique<denoise::EffectLayerDenoiser>(options_.denoiseList());
    // Step: the RT-core model, configured before the scene is loaded (a bad key is the clearer error).
    if (stages_ == Stages::Render && options_.backend == "rtcore") {
        rtcore_ = std::make_unique<rtcore_sim::RtCoreBackend>(options_.rtcoreConfiguration());
        rtcore_->setVerify(options_.verify);
    }
    world_ = std::make_unique<ecs::World>();
    accelBase.threads = options_.threads;
    if (stages_ == Stages::Render) accel_ = std::make_unique<tracer::AccelManager>(accelBase);
}

FrameSession::~FrameSession() = default;

namespace {

// --camera: a camera entity, made the active one.
void setCommandLineCamera(ecs::World& world, const std::string& text) {
    CameraPlacement c = parseCameraPlacement(text);
    if (c.interior) {
        // Step: from the bounds; a flat or empty scene still gets a valid view.
        Aabb bounds = ecs::load::worldBounds(world);
        if (bounds.empty()) bounds = Aabb{vec3(-1.f), vec3(1.f)};
        const vec3 size = glm::max(bounds.extent(), vec3(1e-6f * std::max(1.f, glm::length(bounds.extent()))));
        const vec3 along = size.x >= size.z ? vec3(1.f, 0.f, 0.f) : vec3(0.f, 0.f, 1.f);
        c.eye = vec3(bounds.center().x, bounds.lo.y + 0.35f * size.y, bounds.center().z);
        c.target = c.eye + 0.5f * std::max(size.x, size.z) * along;
    }
    const vec3 along = c.target - c.eye;
    const ecs::Entity e = world.create("command-line camera");
    world.emplace(
        e, ecs::LocalTransform{c.eye, orientationLookingAlong(glm::normalize(along), glm::normalize(c.up)), vec3(1.f)});
    const float distance = glm::length(along);
    world.emplace(e, ecs::Camera{glm::radians(c.fovYDegrees), distance * 1e-4f, distance * 1e4f, 0.f});
    world.setActiveCamera(e);
}

// A load that takes longer than a second says so on stderr: on a terminal,
// "loading SRC (SIZE)..." once the second has passed (cleared when done);
// then, if it succeeded, one line "rtlab: loaded SRC in T s (N triangles)" (a
// log sees only that, and a failed load only its error).
// RTLAB_LOAD_NOTICE_SECONDS sets the threshold (tests use 0).
class SlowLoadNotice {
public:
    explicit SlowLoadNotice(std::string source) : source_(std::move(source)) {
        double threshold = 1.0;
        if (const char* text = std::getenv("RTLAB_LOAD_NOTICE_SECONDS")) {
            char* end = nullptr;
            const double v = std::strtod(text, &end);
            if (end != text && std::isfinite(v) && v >= 0.0) threshold = v;
        }
        watcher_ = std::thread([this, threshold] {
            std::unique_lock lock(mutex_);
            // Threshold 0 announces every load: no race with a load that ends first.
            if (threshold > 0.0 &&
                done_.wait_for(lock, std::chrono::duration<double>(threshold), [&] { return finished_; }))
                return;
            std::string size;
            std::error_code ec;
            const auto bytes = std::filesystem::file_size(source_, ec);
            if (!ec) size = " (" + std::to_string((bytes + 524288) / 1048576) + " MB)";
            if (isatty(STDERR_FILENO)) std::cerr << "rtlab: loading " << source_ << size << "..." << std::flush;
            announced_ = true;
        });
    }
    // Ends the watch; with `triangles`, says how long the load took if it was announced.
    void finish(std::optional<std::size_t> triangles) {
        {
            std::lock_guard lock(mutex_);
            finished_ = true;
        }
        done_.notify_all();
        if (watcher_.joinable()) watcher_.join();
        if (announced_ && isatty(STDERR_FILENO)) std::cerr << "\r\033[K" << std::flush;
        if (announced_ && triangles) {
            char seconds[32];
            std::snprintf(seconds, sizeof seconds, "%.1f", timer_.elapsedMs() / 1000.0);
            std::cerr << "rtlab: loaded " << source_ << " in " << seconds << " s (" << *triangles << " triangles)"
                      << std::endl;
        }
    }
    ~SlowLoadNotice() { finish(std::nullopt); }

private:
    std::string source_;
    Stopwatch timer_;
    std::mutex mutex_;
    std::condition_variable done_;
    bool finished_ = false, announced_ = false;
    std::thread watcher_;
};

}  // namespace

void FrameSession::load() {
    if (loaded_) throw std::logic_error("FrameSession::load: the scene is already loaded");
    SlowLoadNotice notice(options_.scene);
    ecs::load::loadScene(*world_, options_.scene);
    std::size_t triangles = 0;
    world_->each<ecs::MeshInstance>([&](ecs::Entity, const ecs::MeshInstance& inst) {
        if (inst.mesh < world_->meshes().size()) triangles += world_->mesh(inst.mesh).triangleCount();
    });
    notice.finish(triangles);
    if (!options_.camera.empty()) setCommandLineCamera(*world_, options_.camera);
    for (const std::string& w : world_->loadReport().warnings) std::cerr << "rtlab: warning: " << w << "\n";
    loaded_ = true;
}

const FrameState& FrameSession::advance() {
    if (!loaded_) throw std::logic_error("FrameSession::advance before load");
    if (failed_)
        throw std::logic_error(
            "FrameSession::advance after an advance failed (the world, Embree's and the model's structures may "
            "disagree): start a new session");
    // Until this frame is complete, the session counts as failed: an error
    // below may leave the world updated and only one back end's BVHs built.
    failed_ = true;
    // Step: systems -> what changed -> snapshot -> acceleration structures -> plan -> the model's BVHs.
    FrameState next;
    next.index = frame_ ? frame_->index + 1 : 0;
    next.update = world_->update(frame_ ? world_->settings().frameSeconds : 0.f);
    next.scene = ecs::makeSnapshot(*world_, next.update);
    // Step: Embree's BVHs and the model's, built at the same time (they
    // share nothing but the snapshot); Embree's error first.
    runAllInParallel({[&] {
                          if (accel_) next.accel = accel_->update(next.scene);
                      },
                      [&] {
                          if (!rtcore_) return;
                          const Stopwatch clock;
                          next.model = rtcore_->update(next.scene);
                          next.modelUpdateMs = clock.elapsedMs();
                      }});
    next.plan = shaders::planFrame(next.scene, planOptions_);
    if (next.index == 0 && stages_ == Stages::Render)
        for (const std::string& note : next.plan.notes) std::cerr << "rtlab: note: " << note << "\n";
    if (next.scene.untraceableInstances && !warnedUntraceable_) {
        warnedUntraceable_ = true;
        std::cerr << "rtlab: warning: frame " << next.index << ": " << next.scene.untraceableInstances
                  << " mesh instance(s) not traced: a singular or non-finite transform (a zero scale), or one scaling "
                     "by more than 1e12\n";
    }
    frame_ = std::move(next);
    failed_ = false;
    return *frame_;
}

shaders::RenderSettings FrameSession::renderSettings() const {
    if (!frame_) throw std::logic_error("FrameSession::renderSettings before advance");
    shaders::RenderSettings s;
    s.width = options_.width;
    s.height = options_.height;
    s.spp = options_.spp;
    s.frame = frame_->index;
    s.seed = options_.seed;
    s.aoRadius = options_.aoRadius;
    s.aoContactExtraSamples = options_.aoContactSamples;
    s.maxTranslucencyDepth = options_.maxTranslucencyDepth;
    s.pathMaxDepth = options_.maxDepth;
    // The model records which pixel each primary ray came from (heatmaps).
    s.backend = rtcore_.get();
    s.recordRayOrder = rtcore_ != nullptr;
    return s;
}

shaders::FrameOutput FrameSession::render(tracer::TraversalBackend* interpose) {
    if (!accel_) throw std::logic_error("FrameSession::render in a Stages::Plan session");
    if (failed_) throw std::logic_error("FrameSession::render after an advance failed: start a new session");
    shaders::RenderSettings s = renderSettings();
    if (rtcore_) rtcore_->beginFrame();
    if (interpose) s.backend = interpose;
    return shaders::renderFrame(*accel_, frame_->scene, frame_->plan, s, history_);
}

shaders::FrameOutput FrameSession::render(const shaders::RenderSettings& settings,
                                          shaders::FrameHistory& history) const {
    if (!accel_ || !frame_)
        throw std::logic_error("FrameSession::render before advance (or in a Stages::Plan session)");
    if (failed_) throw std::logic_error("FrameSession::render after an advance failed: start a new session");
    return shaders::renderFrame(*accel_, frame_->scene, frame_->plan, settings, history);
}

std::vector<denoise::DenoisedLayer> FrameSession::denoise(shaders::FrameOutput& frame) {
    if (!denoiser_) return {};
    frame.image.addRgbLayer("noisy", frame.image.rgbLayer(""));
    std::vector<denoise::DenoisedLayer> layers = denoiser_->apply(frame.image);
    shaders::composeBeauty(frame.image);
    return layers;
}

std::uint64_t uniqueTriangles(const ecs::SceneSnapshot& scene) {
    std::uint64_t triangles = 0;
    for (const ecs::MeshAsset& mesh : *scene.meshes) triangles += mesh.triangleCount();
    return triangles;
}

}  // namespace rtlab::session
