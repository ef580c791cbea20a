// Primary rays of builtin:showcase through the preview renderer (8-wide
// packets over 16x16 tiles), with 1 and 2 threads. Reports rays per second.
#include <rtlab/core/parallel.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <benchmark/benchmark.h>

namespace {

void BM_PreviewPrimaryRays(benchmark::State& state) {
    const int threads = static_cast<int>(state.range(0));
    const rtlab::ThreadLimit limit(threads);
    rtlab::ecs::World world;
    rtlab::ecs::load::loadScene(world, "builtin:showcase");
    const rtlab::ecs::SceneSnapshot scene = rtlab::ecs::makeSnapshot(world, world.update(0.f));
    rtlab::tracer::AccelManager accel;
    accel.update(scene);
    const rtlab::shaders::PreviewSettings settings{1024, 1024};
    std::uint64_t rays = 0;
    for (auto _ : state) {
        const auto result = rtlab::shaders::renderPreview(accel, scene, settings);
        rays += result.primaryRays;
        benchmark::DoNotOptimize(result.hits);
    }
    state.counters["rays_per_s"] = benchmark::Counter(static_cast<double>(rays), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_PreviewPrimaryRays)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);

}  // namespace

BENCHMARK_MAIN();
