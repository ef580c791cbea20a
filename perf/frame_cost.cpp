// What one denoised 1-spp frame of `rtlab converge` costs, in its two parts:
// the render (shaders::renderFrame of builtin:showcase, static, the G-buffer
// and one effect) and the effect's denoiser (a fresh EffectLayerDenoiser on a
// copy of that frame), as converge times them, with the rtlab binary's malloc
// policy. Per effect (shadows, reflections, ao, gi) and size (320x180,
// 480x270), 2 threads (TBB's default on the development VM). Counters: each
// pass's milliseconds in the last render.
//   BM_RenderFrame/E/S     E: 0 shadows, 1 reflections, 2 ao, 3 gi; S: 0 320x180, 1 480x270
//   BM_DenoiseFrame/E/S
// perf/summarize.py reports frame_cost_ms[effect][size] = {render, denoise}.
#include <rtlab/core/image.hpp>
#include <rtlab/core/memory.hpp>
#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <benchmark/benchmark.h>

#include <array>
#include <map>
#include <memory>
#include <string>

namespace {

using namespace rtlab;

const std::array<const char*, 4> kEffects = {"shadows", "reflections", "ao", "gi"};
const std::array<std::array<int, 2>, 2> kSizes = {{{320, 180}, {480, 270}}};

struct Showcase {
    ecs::World world;
    ecs::SceneSnapshot scene;
    std::unique_ptr<tracer::AccelManager> accel;
    Showcase() {
        ecs::load::loadScene(world, "builtin:showcase");
        scene = ecs::makeSnapshot(world, world.update(0.f));
        accel = std::make_unique<tracer::AccelManager>(tracer::AccelOptions{});
        accel->update(scene);
    }
};

const Showcase& showcase() {
    static const Showcase s;
    return s;
}

shaders::FramePlan planFor(const char* effect) {
    shaders::PlanOptions options;
    options.requested = shaders::parseEffectList(effect);
    return shaders::planFrame(showcase().scene, options);
}

shaders::RenderSettings settingsFor(const benchmark::State& state) {
    shaders::RenderSettings s;
    s.width = kSizes[static_cast<std::size_t>(state.range(1))][0];
    s.height = kSizes[static_cast<std::size_t>(state.range(1))][1];
    s.spp = 1;
    return s;
}

void BM_RenderFrame(benchmark::State& state) {
    const char* effect = kEffects[static_cast<std::size_t>(state.range(0))];
    const shaders::FramePlan plan = planFor(effect);
    const shaders::RenderSettings settings = settingsFor(state);
    shaders::FrameOutput last;
    for (auto _ : state) {
        shaders::FrameOutput frame = shaders::renderFrame(*showcase().accel, showcase().scene, plan, settings);
        benchmark::DoNotOptimize(frame.image.pixelCount());
        last = std::move(frame);
    }
    for (std::size_t p = 0; p < shaders::kPassCount; ++p)
        if (last.passes[p].milliseconds > 0.0)
            state.counters[std::string(shaders::passName(static_cast<shaders::Pass>(p))) + "Ms"] = last.passes[p].milliseconds;
    state.SetLabel(std::string(effect) + " " + std::to_string(settings.width) + "x" + std::to_string(settings.height));
}

void BM_DenoiseFrame(benchmark::State& state) {
    const char* effect = kEffects[static_cast<std::size_t>(state.range(0))];
    const shaders::RenderSettings settings = settingsFor(state);
    const Image frame = shaders::renderFrame(*showcase().accel, showcase().scene, planFor(effect), settings).image;
    for (auto _ : state) {
        state.PauseTiming();
        Image copy = frame;
        state.ResumeTiming();
        denoise::EffectLayerDenoiser({effect}).apply(copy);
        benchmark::DoNotOptimize(copy.pixelCount());
    }
    state.SetLabel(std::string(effect) + " " + std::to_string(settings.width) + "x" + std::to_string(settings.height));
}

BENCHMARK(BM_RenderFrame)->ArgsProduct({{0, 1, 2, 3}, {0, 1}})->MinTime(0.5)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseFrame)->ArgsProduct({{0, 1, 2, 3}, {0, 1}})->MinTime(0.5)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
    // The rtlab binary's malloc policy: what `rtlab converge` pays per frame.
    rtlab::retainFreedMemory();
    benchmark::Initialize(&argc, argv);
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
