// Replay of recorded rays (rtlab replay on Embree) against raw Embree on the
// same rays. The rays: one frame of builtin:terrain?triangles=200000 at
// 256x256 with shadows, AO and two path-trace bounces, recorded through
// study::RecordingBackend. One thread each.
//   BM_ReplayEmbree        study::replayRays (watertight triangles, every
//                          DXR rule, each hit compared with the recording)
//   BM_RawEmbreeSameRays   the same rays packed 8 at a time straight into
//                          rtcIntersect8 / rtcOccluded8 (first-hit rays) on
//                          Embree's native triangles: the floor
// perf/summarize.py reports replay_vs_raw_embree_1t = replay / raw rays per second,
// over all rays and per ray type. RTLAB_REPLAY_SCENE=SRC measures another scene.
#include "bench_scenes.hpp"

#include <rtlab/core/parallel.hpp>
#include <rtlab/study/ray_recorder.hpp>
#include <rtlab/study/replay.hpp>
#include <rtlab/tracer/ray_query.hpp>

#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>

#include <array>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>

namespace {

using namespace rtlab;
const std::string kSource =
    std::getenv("RTLAB_REPLAY_SCENE") ? std::getenv("RTLAB_REPLAY_SCENE") : "builtin:terrain?triangles=200000";

const bench::LoadedScene& scene(bool watertight) {
    static const bench::LoadedScene watertightScene(kSource);
    static const bench::LoadedScene nativeScene(kSource, [] {
        tracer::AccelOptions o;
        o.watertight = false;
        return o;
    }());
    return watertight ? watertightScene : nativeScene;
}

const study::RayTraceFile& recording() {
    static const study::RayTraceFile file = [] {
        session::FrameOptions options;
        options.scene = kSource;
        options.effects = "shadows,ao,pathtrace";
        options.width = options.height = 256;
        options.maxDepth = 2;
        options.denoise = "none";
        session::FrameSession s(options);
        s.load();
        const session::FrameState& frame = s.advance();
        const std::filesystem::path path = std::filesystem::temp_directory_path() / "rtlab_replay_speed.rays";
        study::RecordingBackend recorder(nullptr);
        recorder.beginFrame(path);
        s.render(&recorder);
        recorder.endFrame(0, study::sceneFingerprint(frame.scene), frame.scene.instances.size(), 0);
        return study::RayTraceFile::read(path);
    }();
    return file;
}

// Argument: -1 every ray, else one ray type (shaders::RayType).
std::uint32_t typeMask(const benchmark::State& state) { return state.range(0) < 0 ? 0xffffu : 1u << state.range(0); }

void BM_ReplayEmbree(benchmark::State& state) {
    const ThreadLimit limit(1);
    const study::RayTraceFile& file = recording();
    std::uint64_t rays = 0, differing = 0;
    for (auto _ : state) {
        const study::ReplayResult r = study::replayRays(file, *scene(true).accel, nullptr, typeMask(state));
        rays += r.rays;
        differing += r.differingHits;
    }
    if (differing) state.SkipWithError("replay found differing hits");
    state.counters["rays_per_s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
}

void BM_RawEmbreeSameRays(benchmark::State& state) {
    const ThreadLimit limit(1);
    const study::RayTraceFile& file = recording();
    const RTCScene tlas = scene(false).accel->tlas();
    std::uint64_t rays = 0, hits = 0;
    for (auto _ : state) {
        for (const study::RayTraceFile::Batch& batch : file.batches()) {
            if (!(typeMask(state) >> (batch.record->rayContribution & 0xf) & 1)) continue;
            const bool firstHit = (batch.record->rayFlags & tracer::RayFlag::AcceptFirstHitAndEndSearch) != 0;
            RTCIntersectContext ctx;
            rtcInitIntersectContext(&ctx);
            ctx.flags = batch.record->rayContribution == 0 ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT
                                                           : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
            for (std::size_t first = 0; first < batch.rays.size(); first += 8) {
                alignas(32) std::array<int, 8> valid{};
                alignas(32) RTCRayHit8 rh{};
                for (std::size_t i = 0; i < 8 && first + i < batch.rays.size(); ++i) {
                    const study::RayRecord& r = batch.rays[first + i];
                    valid[i] = -1;
                    rh.ray.org_x[i] = r.origin[0];
                    rh.ray.org_y[i] = r.origin[1];
                    rh.ray.org_z[i] = r.origin[2];
                    rh.ray.dir_x[i] = r.direction[0];
                    rh.ray.dir_y[i] = r.direction[1];
                    rh.ray.dir_z[i] = r.direction[2];
                    rh.ray.tnear[i] = r.tMin;
                    rh.ray.tfar[i] = r.tMax;
                    rh.ray.mask[i] = batch.record->instanceInclusionMask;
                    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
                }
                if (firstHit) {
                    rtcOccluded8(valid.data(), tlas, &ctx, &rh.ray);
                    for (int i = 0; i < 8; ++i) hits += valid[i] && rh.ray.tfar[i] < 0.f;
                } else {
                    rtcIntersect8(valid.data(), tlas, &ctx, &rh);
                    for (int i = 0; i < 8; ++i) hits += valid[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID;
                }
            }
            rays += batch.rays.size();
        }
    }
    benchmark::DoNotOptimize(hits);
    state.counters["rays_per_s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
}

// All rays, then primary (0), shadow (1), AO (3) and path bounces (6) alone.
// The watertight triangles through tracer::queryClosest8 / queryAny8 (no DXR
// rules, no comparison): what the triangles themselves cost.
void BM_QueryApiSameRays(benchmark::State& state) {
    const ThreadLimit limit(1);
    const study::RayTraceFile& file = recording();
    const tracer::AccelManager& accel = *scene(true).accel;
    std::uint64_t rays = 0, hits = 0;
    for (auto _ : state) {
        for (const study::RayTraceFile::Batch& batch : file.batches()) {
            if (!(typeMask(state) >> (batch.record->rayContribution & 0xf) & 1)) continue;
            const bool firstHit = (batch.record->rayFlags & tracer::RayFlag::AcceptFirstHitAndEndSearch) != 0;
            const auto coherence =
                batch.record->rayContribution == 0 ? tracer::RayCoherence::Coherent : tracer::RayCoherence::Incoherent;
            for (std::size_t first = 0; first < batch.rays.size(); first += 8) {
                std::array<tracer::RayDesc, 8> packet;
                std::array<bool, 8> active{};
                for (std::size_t i = 0; i < 8 && first + i < batch.rays.size(); ++i) {
                    packet[i] = study::rayOf(batch.rays[first + i]);
                    active[i] = true;
                }
                if (firstHit) {
                    std::array<bool, 8> any{};
                    tracer::queryAny8(accel, packet.data(), active.data(), any.data(), coherence,
                                      batch.record->instanceInclusionMask);
                    for (int i = 0; i < 8; ++i) hits += active[i] && any[i];
                } else {
                    std::array<tracer::QueryHit, 8> h;
                    tracer::queryClosest8(accel, packet.data(), active.data(), h.data(), coherence,
                                          batch.record->instanceInclusionMask);
                    for (int i = 0; i < 8; ++i) hits += active[i] && h[i].hit;
                }
            }
            rays += batch.rays.size();
        }
    }
    benchmark::DoNotOptimize(hits);
    state.counters["rays_per_s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
}

// Every ray, then primary, shadow, AO and path-bounce rays alone (shaders::RayType).
void rayTypeArguments(benchmark::internal::Benchmark* b) {
    for (const int type : {-1, 0, 1, 3, 6}) b->Arg(type);
    b->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
}

BENCHMARK(BM_ReplayEmbree)->Apply(rayTypeArguments);
BENCHMARK(BM_QueryApiSameRays)->Apply(rayTypeArguments);
BENCHMARK(BM_RawEmbreeSameRays)->Apply(rayTypeArguments);

}  // namespace

BENCHMARK_MAIN();
