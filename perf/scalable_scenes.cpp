// The scalable builtin scenes at study sizes (the tests only load 10^3..10^4
// triangles): load time (scene generation) and acceleration-structure build
// time, with the unique and instanced triangle counts as counters.
//   BM_LoadScalableScene/<source>   one iteration each; the 10^7 sizes need a few GiB
//   BM_TerrainAccelScaling/N        terrain of N = 1e4 .. 4e6 triangles: Embree build
//                                   time and memory (Embree's bytes + the watertight
//                                   clusters'); perf/summarize.py fits their log-log slopes
//   BM_LoadSceneFile/<format>      scene files read back (loadScene): terrain 300k exported as OBJ
//                                  and as PLY (rtlab export's writers), and a glTF of
//                                  assimp-testmodels beside them; MB/s and triangles/s
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/save/scene_writer.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <benchmark/benchmark.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <unistd.h>

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

// The file of `format`: terrain 300k written once per process (removed at exit), or a glTF.
std::filesystem::path sceneFile(const std::string& format) {
    if (format == "gltf") return "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
    struct Files {
        std::filesystem::path dir =
            std::filesystem::temp_directory_path() / ("rtlab_bench_" + std::to_string(::getpid()));
        ~Files() {
            std::error_code ec;
            std::filesystem::remove_all(dir, ec);
        }
    };
    static Files files;
    const std::filesystem::path path = files.dir / ("terrain300k." + format);
    if (!std::filesystem::exists(path)) {
        std::filesystem::create_directories(files.dir);
        ecs::World world;
        ecs::load::loadScene(world, "builtin:terrain?triangles=300000");
        if (format == "obj") ecs::save::writeObj(world, path);
        else ecs::save::writePly(world, path);
    }
    return path;
}

void BM_LoadSceneFile(benchmark::State& state, const std::string& format) {
    const std::filesystem::path path = sceneFile(format);
    const double bytes = static_cast<double>(std::filesystem::file_size(path));
    double triangles = 0.0;
    for (auto _ : state) {
        ecs::World world;
        ecs::load::loadScene(world, path.string());
        triangles = 0.0;
        for (const ecs::MeshAsset& m : world.meshes()) triangles += static_cast<double>(m.triangleCount());
    }
    state.counters["fileMB"] = bytes * 1e-6;
    state.counters["MBPerSecond"] = benchmark::Counter(bytes * 1e-6, benchmark::Counter::kIsIterationInvariantRate);
    state.counters["trianglesPerSecond"] = benchmark::Counter(triangles, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK_CAPTURE(BM_LoadSceneFile, obj, std::string("obj"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_LoadSceneFile, ply, std::string("ply"))->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_LoadSceneFile, gltf, std::string("gltf"))->Unit(benchmark::kMillisecond)->UseRealTime();

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
SCALABLE(slivers_1e6, "builtin:slivers?triangles=1000000");

}  // namespace

BENCHMARK_MAIN();
