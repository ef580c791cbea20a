// What one denoised 1-spp frame of `rtlab converge` costs, in its two parts:
// the render (session::FrameSession::render of builtin:showcase, static, the G-buffer
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
#include <rtlab/session/frame_session.hpp>

#include <benchmark/benchmark.h>

#include <array>
#include <map>
#include <memory>
#include <string>

namespace {

using namespace rtlab;

const std::array<const char*, 4> kEffects = {"shadows", "reflections", "ao", "gi"};
const std::array<std::array<int, 2>, 2> kSizes = {{{320, 180}, {480, 270}}};

// builtin:showcase, static (frame 0), planned for one effect: one frame driver per effect.
session::FrameSession& showcase(const char* effect) {
    static std::map<std::string, std::unique_ptr<session::FrameSession>> sessions;
    std::unique_ptr<session::FrameSession>& s = sessions[effect];
    if (!s) {
        session::FrameOptions options;
        options.scene = "builtin:showcase";
        options.effects = effect;
        s = std::make_unique<session::FrameSession>(options);
        s->load();
        s->advance();
    }
    return *s;
}

shaders::RenderSettings settingsFor(const benchmark::State& state, const char* effect) {
    shaders::RenderSettings s = showcase(effect).renderSettings();
    s.width = kSizes[static_cast<std::size_t>(state.range(1))][0];
    s.height = kSizes[static_cast<std::size_t>(state.range(1))][1];
    s.spp = 1;
    return s;
}

void BM_RenderFrame(benchmark::State& state) {
    const char* effect = kEffects[static_cast<std::size_t>(state.range(0))];
    const session::FrameSession& s = showcase(effect);
    const shaders::RenderSettings settings = settingsFor(state, effect);
    shaders::FrameOutput last;
    for (auto _ : state) {
        shaders::FrameHistory none;
        shaders::FrameOutput frame = s.render(settings, none);
        benchmark::DoNotOptimize(frame.image.pixelCount());
        last = std::move(frame);
    }
    for (std::size_t p = 0; p < shaders::kPassCount; ++p)
        if (last.passes[p].milliseconds > 0.0)
            state.counters[std::string(shaders::passName(static_cast<shaders::Pass>(p))) + "Ms"] =
                last.passes[p].milliseconds;
    state.SetLabel(std::string(effect) + " " + std::to_string(settings.width) + "x" + std::to_string(settings.height));
}

void BM_DenoiseFrame(benchmark::State& state) {
    const char* effect = kEffects[static_cast<std::size_t>(state.range(0))];
    const shaders::RenderSettings settings = settingsFor(state, effect);
    shaders::FrameHistory none;
    const Image frame = showcase(effect).render(settings, none).image;
    for (auto _ : state) {
        state.PauseTiming();
        Image copy = frame;
        state.ResumeTiming();
        denoise::EffectLayerDenoiser({effect}).apply(copy);
        benchmark::DoNotOptimize(copy.pixelCount());
    }
    state.SetLabel(std::string(effect) + " " + std::to_string(settings.width) + "x" + std::to_string(settings.height));
}

BENCHMARK(BM_RenderFrame)
    ->ArgsProduct({{0, 1, 2, 3}, {0, 1}})
    ->MinTime(0.5)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DenoiseFrame)
    ->ArgsProduct({{0, 1, 2, 3}, {0, 1}})
    ->MinTime(0.5)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

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
