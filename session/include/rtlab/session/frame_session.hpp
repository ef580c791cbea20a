#pragma once
// The frame driver: the one place where a frame sequence runs
//   load -> world update -> snapshot -> acceleration structures (Embree and,
//   with --backend rtcore, the RT-core model's BVHs) -> plan -> render -> denoise
// and where FrameOptions become shaders::RenderSettings. rtlab render,
// converge, replay and plan, a study's points (which run rtlab render or
// replay) and the benchmarks all go through it; what they add is their own
// output (files, stats, tables).
//
//   FrameSession session(options);   // options checked, the RT-core model configured
//   session.load();                   // the scene (after the caller made its output directories)
//   for (int f = 0; f < options.frames; ++f) {
//       const FrameState& frame = session.advance();   // update, snapshot, BVHs, plan
//       shaders::FrameOutput out = session.render();    // this frame's settings and history
//       session.denoise(out);                           // --denoise
//   }
#include <rtlab/core/parallel.hpp>
#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/session/frame_options.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <memory>
#include <optional>

namespace rtlab::ecs {
class World;
}
namespace rtlab::rtcore_sim {
class RtCoreBackend;
}

namespace rtlab::session {

// What advance() produced for the current frame.
struct FrameState {
    std::uint32_t index = 0;
    ecs::FrameUpdate update;
    ecs::SceneSnapshot scene;
    tracer::AccelUpdateStats accel;  // Embree's BLAS/TLAS work (none with Stages::Plan)
    shaders::FramePlan plan;
    rtcore_sim::ModelUpdateStats model;  // the RT-core model's BVH work (--backend rtcore)
    double modelUpdateMs = 0.0;
};

// How far a session goes each frame: `rtlab plan` needs no acceleration structures.
enum class Stages { Plan, Render };

class FrameSession {
public:
    // Checks the options (InputError, exit 2, naming the option) and
    // configures the RT-core model; loads nothing yet. `accelBase`: the
    // Embree options a benchmark may vary (its threads come from the options).
    explicit FrameSession(FrameOptions options, Stages stages = Stages::Render, tracer::AccelOptions accelBase = {});
    ~FrameSession();
    FrameSession(const FrameSession&) = delete;
    FrameSession& operator=(const FrameSession&) = delete;

    // Loads the scene; each loader warning goes to stderr as "rtlab: warning: ...".
    void load();
    // The next frame (the first at time 0, then one World::settings().frameSeconds
    // step each): world update, snapshot, Embree's structures, the plan
    // (whose notes go to stderr on the first frame), the model's BVHs.
    // When it throws (Embree out of memory, say), the session is left
    // inconsistent: every later advance() or render() throws std::logic_error.
    const FrameState& advance();
    const FrameState& frame() const { return *frame_; }

    // The current frame's render settings: the only place options become settings.
    shaders::RenderSettings renderSettings() const;
    // Renders the current frame with its settings and the session's history.
    // `interpose` (e.g. study::RecordingBackend) traces instead of the
    // session's back end and forwards to it.
    shaders::FrameOutput render(tracer::TraversalBackend* interpose = nullptr);
    // Renders the current frame's scene and plan with other settings and history (rtlab converge).
    shaders::FrameOutput render(const shaders::RenderSettings& settings, shaders::FrameHistory& history) const;
    // --denoise: filters the effect layers (keeping the noisy beauty as
    // "noisy.*") and composes the beauty again; nothing for none.
    std::vector<denoise::DenoisedLayer> denoise(shaders::FrameOutput& frame);

    const FrameOptions& options() const { return options_; }
    const ecs::World& world() const { return *world_; }
    const tracer::AccelManager& accel() const { return *accel_; }
    // The RT-core model (--backend rtcore), else nullptr.
    rtcore_sim::RtCoreBackend* rtcore() { return rtcore_.get(); }
    const rtcore_sim::RtCoreBackend* rtcore() const { return rtcore_.get(); }

private:
    FrameOptions options_;
    Stages stages_;
    ThreadLimit threadLimit_;
    shaders::PlanOptions planOptions_;
    std::unique_ptr<denoise::EffectLayerDenoiser> denoiser_;
    std::unique_ptr<rtcore_sim::RtCoreBackend> rtcore_;
    std::unique_ptr<ecs::World> world_;
    std::unique_ptr<tracer::AccelManager> accel_;
    std::optional<FrameState> frame_;
    bool warnedUntraceable_ = false;  // the untraceable-instances warning, once per session
    shaders::FrameHistory history_;
    bool loaded_ = false;
    bool failed_ = false;  // an advance() threw: the session cannot go on
};

// The scene's triangles, each mesh counted once however many instances use it.
std::uint64_t uniqueTriangles(const ecs::SceneSnapshot& scene);

}  // namespace rtlab::session
