// Host speed of the RT-core timing model against raw Embree on the same rays:
// builtin:showcase primary rays at 320x240 (argument 0) and one
// cosine-weighted diffuse bounce from every primary hit (argument 1).
//   BM_RtCoreTimingModel  RtCore::run, batches of 1024 rays, cold core per
//                         iteration; second argument: scheduling policy
//                         (0 fifo = default, 1 oldestFirst, 2 treelet). Its
//                         counters are the simulated figures: cyclesPerRay
//                         (frame cycles / rays), meanLatency, nodeVisitsPerRay,
//                         triangleTestsPerRay, cacheHitRate, simdEfficiency
//   BM_RtCoreFunctional   the model's functional traversal (no timing)
//   BM_EmbreeIntersect1   rtcIntersect1 per ray on the same scene: second
//                         argument 1 = the default watertight triangles (the
//                         test the model uses), 0 = Embree's native triangles
//   BM_RtCoreGpu8         the GPU level (issue 14): 8 cores, l2.mode cache, on
//                         showcase (0) and a 10^6-triangle terrain (1), primary (0)
//                         and bounce (1) rays; third argument: host threads —
//                         0 = the serial model (a side that does not allow
//                         concurrent callbacks: one thread, cycle by cycle),
//                         1 / 2 = host-parallel epochs on that many threads
//                         (rtlab::ThreadLimit). CPU time is the process's (all
//                         threads); BM_EmbreeIntersect1Scene: Embree on the
//                         terrain's rays
//   BM_RtCoreLaunch30     launch level (issue 31): the rtx2060-like preset (30
//                         cores, modelled L2 and DRAM) simulating one launch of
//                         the terrain's primary rays, each pixel a thread that
//                         then traces its bounce (RtCore::runLaunch, opaque
//                         verdicts); argument: host threads (1, 2).
//                         BM_EmbreeIntersect1Launch: Embree on the same rays
// All on one thread except BM_RtCoreGpu8/*/*/2; perf/summarize.py turns rays_per_s into
// rtcore_speed_vs_embree_{primary,bounce}[_native] (issue goal: >= 0.125),
// rtcore_speed_gpu8_vs_embree_{showcase,terrain1m}_{primary,bounce} (one host thread, issue 14 goal: >= 0.1)
// and rtcore_speed_gpu8_2t_vs_1t_* (issue 14 goal: >= 1.6),
// rtcore_speed_launch30_vs_embree_terrain1m (issue 31 goal: >= 0.1) and
// rtcore_speed_launch30_2t_vs_1t_terrain1m (issue 31 goal: >= 1.6).
#include "bench_scenes.hpp"

#include <rtlab/core/parallel.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/rtcore_sim/workloads.hpp>

#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>

#include <memory>
#include <string>
#include <span>

namespace {

using namespace rtlab;
using namespace rtlab::rtcore_sim;
constexpr int kWidth = 320, kHeight = 240;
constexpr std::size_t kBatch = 1024;

struct Workload {
    bench::LoadedScene scene;
    std::unique_ptr<bench::LoadedScene> native;  // Embree's native triangles (showcase only)
    RtCoreConfig config;
    std::unique_ptr<ModelScene> model;
    std::vector<SimRay> primary, bounce;
    std::vector<SimRay> launch;               // primary then bounce rays, ...
    std::vector<std::uint32_t> launchThread;  // ... each on its pixel's thread

    Workload(const std::string& source, bool withNative) : scene(source) {
        if (withNative) {
            tracer::AccelOptions o;
            o.watertight = false;
            native = std::make_unique<bench::LoadedScene>(source, o);
        }
        model = std::make_unique<ModelScene>(config.bvh);
        model->update(scene.snapshot);
        const shaders::PinholeCamera camera = scene.camera(kWidth, kHeight);
        for (int y = 0; y < kHeight; ++y)
            for (int x = 0; x < kWidth; ++x) {
                const tracer::RayDesc r = bench::primaryRay(camera, x, y);
                SimRay s;
                s.ray.origin = r.origin;
                s.ray.direction = r.direction;
                primary.push_back(s);
            }
        std::vector<ModelHit> hits(primary.size());
        for (std::size_t i = 0; i < primary.size(); ++i) {
            TraversalCounters c;
            hits[i] = traceClosestHit(*model, primary[i].ray, c);
        }
        bounce = diffuseBounceRays(scene.snapshot, primary, hits);
        // One launch: pixel i's primary ray, then (hits only, in order) its bounce.
        launch = primary;
        for (std::uint32_t i = 0; i < primary.size(); ++i) launchThread.push_back(i);
        std::size_t next = 0;
        for (std::uint32_t i = 0; i < primary.size() && next < bounce.size(); ++i)
            if (hits[i].hit && !hits[i].procedural) {
                launch.push_back(bounce[next++]);
                launchThread.push_back(i);
            }
    }
    const std::vector<SimRay>& rays(std::int64_t which) const { return which == 0 ? primary : bounce; }
};

// 0: builtin:showcase (with a native-triangle Embree scene); 1: a terrain of 10^6 triangles.
const Workload& workload(std::int64_t which = 0) {
    if (which == 1) {
        static const Workload terrain("builtin:terrain?triangles=1000000", false);
        return terrain;
    }
    static const Workload w("builtin:showcase", true);
    return w;
}

void setRate(benchmark::State& state, std::size_t rays) {
    state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * rays));
    state.counters["rays_per_s"] =
        benchmark::Counter(static_cast<double>(rays), benchmark::Counter::kIsIterationInvariantRate);
}

constexpr const char* kPolicies[] = {"fifo", "oldestFirst", "treelet"};

void BM_RtCoreTimingModel(benchmark::State& state) {
    const Workload& w = workload();
    const std::vector<SimRay>& rays = w.rays(state.range(0));
    RtCoreConfig config = w.config;
    config.scheduler.policy = kPolicies[state.range(1)];
    state.SetLabel(std::string(state.range(0) == 0 ? "primary " : "bounce ") + kPolicies[state.range(1)]);
    RtCore core(config, *w.model);
    std::vector<SimRayResult> results(rays.size());
    OpaqueSide side;
    for (auto _ : state) {
        core.reset();
        for (std::size_t first = 0; first < rays.size(); first += kBatch) {
            const std::size_t n = std::min(kBatch, rays.size() - first);
            core.run(std::span(rays).subspan(first, n), side, std::span(results).subspan(first, n));
        }
        benchmark::DoNotOptimize(results.data());
    }
    setRate(state, rays.size());
    const nlohmann::json stats = core.statsJson();
    const double n = static_cast<double>(rays.size());
    state.counters["cycles"] = static_cast<double>(core.cycle());
    state.counters["cyclesPerRay"] = static_cast<double>(core.cycle()) / n;
    state.counters["meanLatency"] = stats["rays"]["latency"]["mean"].get<double>();
    state.counters["nodeVisitsPerRay"] = stats["rays"]["nodeVisits"]["mean"].get<double>();
    state.counters["triangleTestsPerRay"] = stats["rays"]["triangleTests"]["mean"].get<double>();
    state.counters["cacheHitRate"] = stats["cache"]["hitRate"].get<double>();
    state.counters["simdEfficiency"] = stats["simd"]["efficiency"].get<double>();
}

void BM_RtCoreFunctional(benchmark::State& state) {
    const Workload& w = workload();
    const std::vector<SimRay>& rays = w.rays(state.range(0));
    for (auto _ : state) {
        std::uint64_t hits = 0;
        for (const SimRay& r : rays) {
            TraversalCounters c;
            hits += traceClosestHit(*w.model, r.ray, c).hit;
        }
        benchmark::DoNotOptimize(hits);
    }
    setRate(state, rays.size());
}

void embreeLoop(benchmark::State& state, RTCScene tlas, const std::vector<SimRay>& rays);

void BM_EmbreeIntersect1(benchmark::State& state) {
    const Workload& w = workload();
    const std::vector<SimRay>& rays = w.rays(state.range(0));
    const RTCScene tlas = state.range(1) != 0 ? w.scene.accel->tlas() : w.native->accel->tlas();
    embreeLoop(state, tlas, rays);
}

// rtcIntersect1, watertight triangles, on workload range(0) (0 showcase, 1 terrain 10^6), rays range(1).
void BM_EmbreeIntersect1Scene(benchmark::State& state) {
    const Workload& w = workload(state.range(0));
    embreeLoop(state, w.scene.accel->tlas(), w.rays(state.range(1)));
}

// OpaqueSide without concurrent callbacks: RtCore runs the serial model.
struct SerialOpaqueSide final : ProgrammableSide {
    CandidateVerdict triangle(std::uint32_t, const TriangleCandidate&) override { return {}; }
    ProceduralVerdict procedural(std::uint32_t, const ProceduralCandidate&) override { return {}; }
};

// The GPU level: 8 cores, L2 in mode cache, batches of 8192 rays (32 warps
// per core), cold GPU per iteration; workload range(0), rays range(1), host
// threads range(2) (0 = the serial model on one thread).
void BM_RtCoreGpu8(benchmark::State& state) {
    const Workload& w = workload(state.range(0));
    const std::vector<SimRay>& rays = w.rays(state.range(1));
    const int threads = static_cast<int>(state.range(2));
    const ThreadLimit limit(std::max(threads, 1));
    RtCoreConfig config = w.config;
    config.gpu.cores = 8;
    config.l2.mode = L2Mode::Cache;
    state.SetLabel(std::string(state.range(0) == 0 ? "showcase " : "terrain1M ") +
                   (state.range(1) == 0 ? "primary " : "bounce ") +
                   (threads == 0 ? "serial" : std::to_string(threads) + "t"));
    RtCore gpu(config, *w.model);
    std::vector<SimRayResult> results(rays.size());
    OpaqueSide parallelSide;
    SerialOpaqueSide serialSide;
    ProgrammableSide& side = threads == 0 ? static_cast<ProgrammableSide&>(serialSide) : parallelSide;
    constexpr std::size_t kGpuBatch = 8192;
    for (auto _ : state) {
        gpu.reset();
        for (std::size_t first = 0; first < rays.size(); first += kGpuBatch) {
            const std::size_t n = std::min(kGpuBatch, rays.size() - first);
            gpu.run(std::span(rays).subspan(first, n), side, std::span(results).subspan(first, n));
        }
        benchmark::DoNotOptimize(results.data());
    }
    setRate(state, rays.size());
    const nlohmann::json stats = gpu.statsJson();
    state.counters["cyclesPerRay"] = static_cast<double>(gpu.cycle()) / static_cast<double>(rays.size());
    state.counters["l2HitRate"] = stats["l2"]["hitRate"].get<double>();
    state.counters["dramUtilization"] = stats["dram"]["utilization"].get<double>();
}

// Launch level: the terrain's primary and bounce rays as one launch on the
// rtx2060-like preset, cold GPU per iteration; host threads range(0).
void BM_RtCoreLaunch30(benchmark::State& state) {
    const Workload& w = workload(1);
    const int threads = static_cast<int>(state.range(0));
    const ThreadLimit limit(threads);
    const RtCoreConfig config = RtCoreConfig::load("rtx2060-like");
    state.SetLabel("terrain1M launch, rtx2060-like, " + std::to_string(threads) + "t");
    RtCore gpu(config, *w.model);
    std::vector<SimRayResult> results(w.launch.size());
    OpaqueSide side;
    for (auto _ : state) {
        gpu.reset();
        gpu.runLaunch(w.launch, w.launchThread, static_cast<std::uint32_t>(w.primary.size()), side, results);
        benchmark::DoNotOptimize(results.data());
    }
    setRate(state, w.launch.size());
    state.counters["cyclesPerRay"] = static_cast<double>(gpu.cycle()) / static_cast<double>(w.launch.size());
}

void BM_EmbreeIntersect1Launch(benchmark::State& state) {
    const Workload& w = workload(1);
    embreeLoop(state, w.scene.accel->tlas(), w.launch);
}

void embreeLoop(benchmark::State& state, RTCScene tlas, const std::vector<SimRay>& rays) {
    for (auto _ : state) {
        std::uint64_t hits = 0;
        for (const SimRay& r : rays) {
            RTCIntersectContext ctx;
            rtcInitIntersectContext(&ctx);
            RTCRayHit rh{};
            rh.ray.org_x = r.ray.origin.x;
            rh.ray.org_y = r.ray.origin.y;
            rh.ray.org_z = r.ray.origin.z;
            rh.ray.dir_x = r.ray.direction.x;
            rh.ray.dir_y = r.ray.direction.y;
            rh.ray.dir_z = r.ray.direction.z;
            rh.ray.tnear = r.ray.tMin;
            rh.ray.tfar = r.ray.tMax;
            rh.ray.mask = 0xff;
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(tlas, &ctx, &rh);
            hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
        }
        benchmark::DoNotOptimize(hits);
    }
    setRate(state, rays.size());
}

}  // namespace

BENCHMARK(BM_RtCoreTimingModel)
    ->ArgsProduct({{0, 1}, {0, 1, 2}})
    ->MinTime(1.0)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RtCoreFunctional)->Arg(0)->Arg(1)->MinTime(1.0)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EmbreeIntersect1)
    ->ArgsProduct({{0, 1}, {1, 0}})
    ->MinTime(1.0)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RtCoreGpu8)
    ->ArgsProduct({{0, 1}, {0, 1}, {0, 1, 2}})
    ->MinTime(1.0)
    ->UseRealTime()
    ->MeasureProcessCPUTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EmbreeIntersect1Scene)
    ->ArgsProduct({{1}, {0, 1}})
    ->MinTime(1.0)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RtCoreLaunch30)
    ->Arg(1)
    ->Arg(2)
    ->MinTime(1.0)
    ->UseRealTime()
    ->MeasureProcessCPUTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EmbreeIntersect1Launch)->MinTime(1.0)->UseRealTime()->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
