// The scalable builtin scenes at study sizes (the tests only load 10^3..10^4
// triangles): load time (scene generation) and acceleration-structure build
// time, with the unique and instanced triangle counts as counters.
//   BM_LoadScalableScene/<source>   one iteration each; the 10^7 sizes need a few GiB
//   BM_TerrainAccelScaling/N        terrain of N = 1e4 .. 4e6 triangles: Embree build
//                                   time and memory (Embree's bytes + the watertight
//                                   clusters'); perf/summarize.py fits their log-log slopes
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <benchmark/benchmark.h>

#include <chrono>
#include <string>

namespace {

using namespace rtlab;

double msSince(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

void BM_LoadScalableScene(benchmark::State& state, const std::string& source) {
    for (auto _ : state) {
        const auto start = std::chrono::steady_clock::now();
        ecs::World world;
        ecs::load::loadScene(world, source);
        const double loadMs = msSince(start);
        double unique = 0.0, instanced = 0.0;
        for (const ecs::MeshAsset& m : world.meshes()) unique += static_cast<double>(m.triangleCount());
        world.each<ecs::MeshInstance>([&](ecs::Entity, const ecs::MeshInstance& inst) {
            instanced += static_cast<double>(world.mesh(inst.mesh).triangleCount());
        });
        tracer::AccelManager accel;
        const tracer::AccelUpdateStats s = accel.update(ecs::makeSnapshot(world, world.update(0.f)));
        state.counters["loadMs"] = loadMs;
        state.counters["buildMs"] = s.buildMs;
        state.counters["uniqueTriangles"] = unique;
        state.counters["instancedTriangles"] = instanced;
    }
}

void BM_TerrainAccelScaling(benchmark::State& state) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:terrain?triangles=" + std::to_string(state.range(0)));
    const ecs::SceneSnapshot snapshot = ecs::makeSnapshot(world, world.update(0.f));
    double unique = 0.0;
    for (const ecs::MeshAsset& m : world.meshes()) unique += static_cast<double>(m.triangleCount());
    for (auto _ : state) {
        tracer::AccelManager accel;  // a fresh device: its bytes are this build's
        const tracer::AccelUpdateStats s = accel.update(snapshot);
        state.counters["buildMs"] = s.buildMs;
        state.counters["embreeBytes"] = static_cast<double>(accel.embreeBytes());
        state.counters["clusterBytes"] = static_cast<double>(accel.clusterBytes());
        state.counters["bytesPerTriangle"] = static_cast<double>(accel.embreeBytes() + accel.clusterBytes()) / unique;
    }
    state.counters["uniqueTriangles"] = unique;
}
BENCHMARK(BM_TerrainAccelScaling)
    ->Arg(10000)
    ->Arg(30000)
    ->Arg(100000)
    ->Arg(300000)
    ->Arg(1000000)
    ->Arg(2000000)
    ->Arg(4000000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

#define SCALABLE(name, source) \
    BENCHMARK_CAPTURE(BM_LoadScalableScene, name, std::string(source))->Iterations(1)->Unit(benchmark::kMillisecond)
SCALABLE(terrain_1e5, "builtin:terrain?triangles=100000");
SCALABLE(terrain_1e6, "builtin:terrain?triangles=1000000");
SCALABLE(terrain_1e7, "builtin:terrain?triangles=10000000");
SCALABLE(forest_1e3, "builtin:forest?instances=1000");
SCALABLE(forest_1e4, "builtin:forest?instances=10000");
SCALABLE(forest_1e5, "builtin:forest?instances=100000");
SCALABLE(hairball_1e5, "builtin:hairball?triangles=100000");
SCALABLE(hairball_1e6, "builtin:hairball?triangles=1000000");
SCALABLE(hairball_1e7, "builtin:hairball?triangles=10000000");

}  // namespace

BENCHMARK_MAIN();
