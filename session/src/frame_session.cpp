// The frame driver (frame_session.hpp).
#include <rtlab/session/frame_session.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/timer.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>

#include <iostream>
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

// --camera "ex,ey,ez,tx,ty,tz[,ux,uy,uz[,fovYDegrees]]": a camera entity, made the active one.
void setCommandLineCamera(ecs::World& world, const std::string& text) {
    std::vector<float> v;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) {
        char* end = nullptr;
        const float x = std::strtof(item.c_str(), &end);
        if (item.empty() || end != item.c_str() + item.size() || !std::isfinite(x))
            throw InputError("--camera", "'" + item + "' is not a finite number");
        v.push_back(x);
    }
    if (v.size() != 6 && v.size() != 9 && v.size() != 10)
        throw InputError("--camera", "expected 6, 9 or 10 numbers: eye, target[, up[, fovY in degrees]] (got " +
                                         std::to_string(v.size()) + ")");
    const vec3 eye(v[0], v[1], v[2]), target(v[3], v[4], v[5]);
    const vec3 up = v.size() >= 9 ? vec3(v[6], v[7], v[8]) : vec3(0.f, 1.f, 0.f);
    const float fovY = v.size() == 10 ? v[9] : 45.f;
    const vec3 along = target - eye;
    if (!(glm::length(along) > 0.f)) throw InputError("--camera", "eye and target are the same point");
    if (!(glm::length(glm::cross(along, up)) > 1e-6f * glm::length(along) * glm::length(up)))
        throw InputError("--camera", "the up vector is zero or along the view direction");
    if (!(fovY > 0.f && fovY < 180.f)) throw InputError("--camera", "fovY must be in (0, 180) degrees");
    const ecs::Entity e = world.create("command-line camera");
    world.emplace(
        e, ecs::LocalTransform{eye, orientationLookingAlong(glm::normalize(along), glm::normalize(up)), vec3(1.f)});
    const float distance = glm::length(along);
    world.emplace(e, ecs::Camera{glm::radians(fovY), distance * 1e-4f, distance * 1e4f, 0.f});
    world.setActiveCamera(e);
}

}  // namespace

void FrameSession::load() {
    if (loaded_) throw std::logic_error("FrameSession::load: the scene is already loaded");
    ecs::load::loadScene(*world_, options_.scene);
    if (!options_.camera.empty()) setCommandLineCamera(*world_, options_.camera);
    for (const std::string& w : world_->loadReport().warnings) std::cerr << "rtlab: warning: " << w << "\n";
    loaded_ = true;
}

const FrameState& FrameSession::advance() {
    if (!loaded_) throw std::logic_error("FrameSession::advance before load");
    // Step: systems -> what changed -> snapshot -> acceleration structures -> plan -> the model's BVHs.
    FrameState next;
    next.index = frame_ ? frame_->index + 1 : 0;
    next.update = world_->update(frame_ ? world_->settings().frameSeconds : 0.f);
    next.scene = ecs::makeSnapshot(*world_, next.update);
    if (accel_) next.accel = accel_->update(next.scene);
    next.plan = shaders::planFrame(next.scene, planOptions_);
    if (next.index == 0 && stages_ == Stages::Render)
        for (const std::string& note : next.plan.notes) std::cerr << "rtlab: note: " << note << "\n";
    if (rtcore_) {
        const Stopwatch clock;
        next.model = rtcore_->update(next.scene);
        next.modelUpdateMs = clock.elapsedMs();
    }
    frame_ = std::move(next);
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
    shaders::RenderSettings s = renderSettings();
    if (rtcore_) rtcore_->beginFrame();
    if (interpose) s.backend = interpose;
    return shaders::renderFrame(*accel_, frame_->scene, frame_->plan, s, history_);
}

shaders::FrameOutput FrameSession::render(const shaders::RenderSettings& settings,
                                          shaders::FrameHistory& history) const {
    if (!accel_ || !frame_)
        throw std::logic_error("FrameSession::render before advance (or in a Stages::Plan session)");
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
