// Retained acceleration structures: what each kind of FrameUpdate costs.
//   BM_Rebuild1M / BM_Refit1M   a ~1M-triangle deforming grid: topology change
//                               (BLAS rebuild) vs vertex change (BLAS refit);
//                               argument 1 = watertight triangles (default), 0 = native
//   BM_FullBuild1000 / BM_OneMoves1000
//                               1000 instances of distinct meshes: building
//                               everything from scratch vs a frame where one
//                               instance moves (world.update + snapshot + TLAS)
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <benchmark/benchmark.h>

#include <cmath>

namespace {

using namespace rtlab;

constexpr int kGridQuads = 708;  // 708 x 708 x 2 = 1,002,528 triangles

tracer::AccelOptions options(bool watertight) {
    tracer::AccelOptions o;
    o.watertight = watertight;
    return o;
}

struct DeformingGrid {
    ecs::World world;
    ecs::MeshId mesh = 0;
    tracer::AccelManager accel;
    float phase = 0.f;

    explicit DeformingGrid(bool watertight) : accel(options(watertight)) {
        ecs::Geometry g = ecs::load::makeGrid(10.f, kGridQuads, 0);
        g.restPositions = g.positions;  // deformable: keeps a refittable BVH
        g.restNormals = g.normals;
        ecs::MorphTarget wave;
        for (const vec3& p : g.positions)
            wave.positionDeltas.emplace_back(0.f, 0.3f * std::sin(3.f * p.x + 2.f * p.z), 0.f);
        g.morphTargets.push_back(std::move(wave));
        world.addMaterial({});
        mesh = world.addMesh(ecs::load::makeMesh("grid", std::move(g)));
        const ecs::Entity e = world.create("grid");
        world.emplace(e, ecs::MeshInstance{mesh});
        world.emplace(e, ecs::MorphWeights{{0.f}});
        accel.update(ecs::makeSnapshot(world, world.update(0.f)));
    }
};

void BM_Refit1M(benchmark::State& state) {
    DeformingGrid grid(state.range(0) != 0);
    const ecs::Entity e{0, 0};
    double accelMs = 0.0;
    for (auto _ : state) {
        grid.phase += 0.05f;
        grid.world.patch<ecs::MorphWeights>(e, [&](ecs::MorphWeights& w) { w.weights[0] = std::sin(grid.phase); });
        const ecs::SceneSnapshot snap = ecs::makeSnapshot(grid.world, grid.world.update(0.04f));
        const tracer::AccelUpdateStats s = grid.accel.update(snap);
        if (s.blasRefit != 1) state.SkipWithError("expected a refit");
        accelMs += s.buildMs;
    }
    state.counters["accel_ms"] = accelMs / state.iterations();
}

void BM_Rebuild1M(benchmark::State& state) {
    DeformingGrid grid(state.range(0) != 0);
    double accelMs = 0.0;
    for (auto _ : state) {
        state.PauseTiming();
        ecs::MeshAsset copy = grid.world.mesh(grid.mesh);
        state.ResumeTiming();
        grid.world.replaceMesh(grid.mesh, std::move(copy));
        const ecs::SceneSnapshot snap = ecs::makeSnapshot(grid.world, grid.world.update(0.04f));
        const tracer::AccelUpdateStats s = grid.accel.update(snap);
        if (s.blasRebuilt != 1) state.SkipWithError("expected a rebuild");
        accelMs += s.buildMs;
    }
    state.counters["accel_ms"] = accelMs / state.iterations();
}

struct ThousandInstances {
    ecs::World world;
    std::vector<ecs::Entity> entities;
    ThousandInstances() {
        world.addMaterial({});
        for (int i = 0; i < 1000; ++i) {
            const ecs::MeshId m = world.addMesh(ecs::load::makeMesh("sphere", ecs::load::makeIcosphere(0.4f, 2, 0)));
            const ecs::Entity e = world.create();
            world.emplace(e, ecs::LocalTransform{vec3(float(i % 32), float((i / 32) % 32), float(i / 1024))});
            world.emplace(e, ecs::MeshInstance{m});
            entities.push_back(e);
        }
    }
};

void BM_FullBuild1000(benchmark::State& state) {
    ThousandInstances scene;
    const ecs::SceneSnapshot snap = ecs::makeSnapshot(scene.world, scene.world.update(0.f));
    for (auto _ : state) {
        tracer::AccelManager accel;
        benchmark::DoNotOptimize(accel.update(snap));
    }
}

void BM_OneMoves1000(benchmark::State& state) {
    ThousandInstances scene;
    tracer::AccelManager accel;
    accel.update(ecs::makeSnapshot(scene.world, scene.world.update(0.f)));
    float x = 0.f;
    for (auto _ : state) {
        x += 0.01f;
        scene.world.patch<ecs::LocalTransform>(scene.entities[500],
                                               [&](ecs::LocalTransform& t) { t.translation.x = x; });
        const ecs::SceneSnapshot snap = ecs::makeSnapshot(scene.world, scene.world.update(0.04f));
        const tracer::AccelUpdateStats s = accel.update(snap);
        if (s.instancesMoved != 1 || s.blasRebuilt != 0) state.SkipWithError("expected one moved instance");
    }
}

BENCHMARK(BM_Refit1M)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);
BENCHMARK(BM_Rebuild1M)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);
BENCHMARK(BM_FullBuild1000)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_OneMoves1000)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);

}  // namespace

BENCHMARK_MAIN();
