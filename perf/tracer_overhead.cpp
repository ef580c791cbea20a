// Pipeline overhead against raw Embree, packet vs single ray, thread scaling.
// All on the same primary rays of builtin:showcase at 1024x1024.
//   BM_RawIntersect8      8-ray packets over 16x16 tiles, no shaders (the floor):
//                         the watertight default through tracer::queryClosest8
//                         (the traversal the pipeline runs), Embree's native
//                         triangles through rtcIntersect8 itself
//   BM_RawIntersect8Bounce the same over cosine-weighted diffuse bounce rays
//                         from every primary hit (incoherent), one thread
//   BM_PipelinePacket     Pipeline::dispatchCoherent, trivial closest-hit/miss
//   BM_PipelineSingleRay  Pipeline::dispatchRays + traceRay per pixel
// Each runs with 1 and 2 threads (first argument) and with the default
// watertight triangles (second argument 1) or Embree's native robust
// triangles (0); perf/summarize.py turns them into ratios.
#include "bench_scenes.hpp"

#include <rtlab/core/parallel.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>
#include <rtlab/rtcore_sim/workloads.hpp>
#include <rtlab/tracer/pipeline.hpp>
#include <rtlab/tracer/ray_query.hpp>

#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>

#include <algorithm>
#include <array>

namespace {

using namespace rtlab;
constexpr int kSize = 1024;

const bench::LoadedScene& showcase(bool watertight) {
    static const bench::LoadedScene watertightScene("builtin:showcase");
    static const bench::LoadedScene nativeScene("builtin:showcase", [] {
        tracer::AccelOptions o;
        o.watertight = false;
        return o;
    }());
    return watertight ? watertightScene : nativeScene;
}

struct HitPayload {
    float t = 0.f;
};

tracer::Pipeline<HitPayload>::Desc trivialShaders(const tracer::AccelManager& accel) {
    tracer::Pipeline<HitPayload>::Desc desc;
    desc.hitGroups.resize(accel.geometrySlotCount());
    for (auto& g : desc.hitGroups)
        g.closestHit = [](const tracer::HitContext& ctx, HitPayload& p, const tracer::HitAttributes&) {
            p.t = ctx.rayTCurrent;
        };
    desc.missShaders.push_back([](const tracer::MissContext&, HitPayload& p) { p.t = -1.f; });
    return desc;
}

// One packet of up to 8 rays, closest hits' t (-1 for a miss) into out:
// watertight scenes through the tracer's query (ray_query.hpp), native ones
// straight through rtcIntersect8 with Embree's own context.
void tracePacket(const tracer::AccelManager& accel, const tracer::RayDesc* rays, const bool* active, float* out,
                 tracer::RayCoherence coherence, bool forceQuery = false) {
    if (accel.options().watertight || forceQuery) {
        std::array<tracer::QueryHit, 8> hits;
        tracer::queryClosest8(accel, rays, active, hits.data(), coherence);
        for (int i = 0; i < 8; ++i)
            if (active[i]) out[i] = hits[i].hit ? hits[i].t : -1.f;
        return;
    }
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = coherence == tracer::RayCoherence::Coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT
                                                            : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    alignas(32) std::array<int, 8> valid{};
    alignas(32) RTCRayHit8 rh{};
    for (int i = 0; i < 8; ++i) {
        valid[i] = active[i] ? -1 : 0;
        const tracer::RayDesc& r = rays[i];
        rh.ray.org_x[i] = r.origin.x;
        rh.ray.org_y[i] = r.origin.y;
        rh.ray.org_z[i] = r.origin.z;
        rh.ray.dir_x[i] = r.direction.x;
        rh.ray.dir_y[i] = r.direction.y;
        rh.ray.dir_z[i] = r.direction.z;
        rh.ray.tnear[i] = r.tMin;
        rh.ray.tfar[i] = r.tMax;
        rh.ray.mask[i] = 0xff;
        rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect8(valid.data(), accel.tlas(), &ctx, &rh);
    for (int i = 0; i < 8; ++i)
        if (active[i]) out[i] = rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID ? -1.f : rh.ray.tfar[i];
}

void BM_RawIntersect8(benchmark::State& state) {
    const ThreadLimit limit(static_cast<int>(state.range(0)));
    const auto& scene = showcase(state.range(1) != 0);
    const shaders::PinholeCamera camera = scene.camera(kSize, kSize);
    const std::vector<Tile> tiles = makeTiles(kSize, kSize, 16);
    std::vector<float> out(static_cast<std::size_t>(kSize) * kSize);
    for (auto _ : state) {
        parallelForEach(tiles.size(), [&](std::size_t ti) {
            const Tile& tile = tiles[ti];
            for (int y = tile.y0; y < tile.y1; ++y)
                for (int x0 = tile.x0; x0 < tile.x1; x0 += 8) {
                    std::array<tracer::RayDesc, 8> rays;
                    std::array<bool, 8> active{};
                    alignas(32) std::array<float, 8> t{};
                    for (int i = 0; i < 8; ++i) {
                        active[i] = x0 + i < tile.x1;
                        if (active[i]) rays[i] = bench::primaryRay(camera, x0 + i, y);
                    }
                    tracePacket(*scene.accel, rays.data(), active.data(), t.data(), tracer::RayCoherence::Coherent);
                    for (int i = 0; i < 8 && x0 + i < tile.x1; ++i)
                        out[static_cast<std::size_t>(y) * kSize + x0 + i] = t[i];
                }
        });
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["rays_per_s"] =
        benchmark::Counter(double(kSize) * kSize * state.iterations(), benchmark::Counter::kIsRate);
}

// Diffuse bounce rays of the showcase at 512x512 (the RT-core model finds
// the primary hits; both back ends give the same ones).
const std::vector<rtcore_sim::SimRay>& bounceRays() {
    static const std::vector<rtcore_sim::SimRay> rays = [] {
        const auto& scene = showcase(true);
        rtcore_sim::ModelScene model(rtcore_sim::BvhParams{});
        model.update(scene.snapshot);
        const shaders::PinholeCamera camera = scene.camera(512, 512);
        std::vector<rtcore_sim::SimRay> primary;
        for (int y = 0; y < 512; ++y)
            for (int x = 0; x < 512; ++x) {
                const tracer::RayDesc r = bench::primaryRay(camera, x, y);
                rtcore_sim::SimRay s;
                s.ray.origin = r.origin;
                s.ray.direction = r.direction;
                primary.push_back(s);
            }
        std::vector<rtcore_sim::ModelHit> hits(primary.size());
        for (std::size_t i = 0; i < primary.size(); ++i) {
            rtcore_sim::TraversalCounters c;
            hits[i] = rtcore_sim::traceClosestHit(model, primary[i].ray, c);
        }
        return rtcore_sim::diffuseBounceRays(scene.snapshot, primary, hits);
    }();
    return rays;
}

// Argument: 1 watertight, 0 native triangles through rtcIntersect8, 2 native
// triangles through the same query API as the watertight ones (what the
// API's set-up costs, apart from the triangles).
void BM_RawIntersect8Bounce(benchmark::State& state) {
    const ThreadLimit limit(1);
    const auto& scene = showcase(state.range(0) == 1);
    const bool viaQuery = state.range(0) == 2;
    const std::vector<rtcore_sim::SimRay>& rays = bounceRays();
    std::vector<float> out(rays.size());
    for (auto _ : state) {
        for (std::size_t first = 0; first < rays.size(); first += 8) {
            std::array<tracer::RayDesc, 8> packet;
            std::array<bool, 8> active{};
            alignas(32) std::array<float, 8> t{};
            for (std::size_t i = 0; i < 8 && first + i < rays.size(); ++i) {
                const rtcore_sim::ModelRay& r = rays[first + i].ray;
                packet[i] = tracer::RayDesc{r.origin, r.tMin, r.direction, r.tMax};
                active[i] = true;
            }
            tracePacket(*scene.accel, packet.data(), active.data(), t.data(), tracer::RayCoherence::Incoherent,
                        viaQuery);
            for (std::size_t i = 0; i < 8 && first + i < rays.size(); ++i) out[first + i] = t[i];
        }
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["rays_per_s"] =
        benchmark::Counter(double(rays.size()) * state.iterations(), benchmark::Counter::kIsRate);
}

void BM_PipelinePacket(benchmark::State& state) {
    const ThreadLimit limit(static_cast<int>(state.range(0)));
    const auto& scene = showcase(state.range(1) != 0);
    const shaders::PinholeCamera camera = scene.camera(kSize, kSize);
    const tracer::Pipeline<HitPayload> pipeline(*scene.accel, trivialShaders(*scene.accel));
    std::vector<float> out(static_cast<std::size_t>(kSize) * kSize);
    for (auto _ : state) {
        pipeline.dispatchCoherent(
            kSize, kSize, tracer::TraceArgs{},
            [&](int x, int y, HitPayload&) { return bench::primaryRay(camera, x, y); },
            [&](int x, int y, const HitPayload& p) { out[static_cast<std::size_t>(y) * kSize + x] = p.t; });
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["rays_per_s"] =
        benchmark::Counter(double(kSize) * kSize * state.iterations(), benchmark::Counter::kIsRate);
}

void BM_PipelineSingleRay(benchmark::State& state) {
    const ThreadLimit limit(static_cast<int>(state.range(0)));
    const auto& scene = showcase(state.range(1) != 0);
    const shaders::PinholeCamera camera = scene.camera(kSize, kSize);
    const tracer::Pipeline<HitPayload> pipeline(*scene.accel, trivialShaders(*scene.accel));
    std::vector<float> out(static_cast<std::size_t>(kSize) * kSize);
    for (auto _ : state) {
        pipeline.dispatchRays(kSize, kSize, [&](int x, int y) {
            HitPayload p;
            pipeline.traceRay(tracer::TraceArgs{}, bench::primaryRay(camera, x, y), p);
            out[static_cast<std::size_t>(y) * kSize + x] = p.t;
        });
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["rays_per_s"] =
        benchmark::Counter(double(kSize) * kSize * state.iterations(), benchmark::Counter::kIsRate);
}

BENCHMARK(BM_RawIntersect8)->ArgsProduct({{1, 2}, {1, 0}})->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_RawIntersect8Bounce)->Arg(1)->Arg(0)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_PipelinePacket)->ArgsProduct({{1, 2}, {1, 0}})->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_PipelineSingleRay)
    ->ArgsProduct({{1, 2}, {1, 0}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(1.0);

}  // namespace

BENCHMARK_MAIN();
