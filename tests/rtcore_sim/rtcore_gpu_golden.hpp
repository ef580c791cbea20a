#pragma once
// Workloads and a digest for the host-thread tests of the GPU level
// (test_rtcore_gpu.cpp, RtCoreGpu.HostParallelEpochsReproduceTheSerialGpuModel):
// the digests in rtcore_gpu_golden_values.inc were computed by this very code
// linked against the GPU model as it was before host-parallel epochs (commit
// e3caa2e, one host thread, cycle by cycle), so the test fails if host
// parallelism changes any cycle or statistic of several cores.
#include "rtcore_golden.hpp"

#include <rtlab/rtcore_sim/workloads.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim::test_support {

// Workload `which` (all with several cores; primary rays 64x48 with two ray
// types, then one diffuse bounce from every hit, batches of 1000):
//   0 showcase, 8 cores, l2 cache, defaults
//   1 terrain (20 k triangles), 8 cores, l2 cache, treeletPrefetch, small L1 and
//     L2 (bank conflicts, DRAM queueing), a short stack (spills, refills)
//   2 showcase, 8 cores, l2 cache, contiguous dispatch, oldestFirst, a node-cache
//     hit latency (400) longer than the shortest L2 round trip (2 + 4 + 20)
//   3 forest (40 instances), 8 cores, l2 ideal, treelet
//   4 showcase, 3 cores, l2 cache, scarce queues and slots, warps of 8
inline constexpr int kGpuGoldenWorkloads = 5;

inline std::string gpuGoldenSource(int which) {
    switch (which) {
        case 1: return "builtin:terrain?triangles=20000";
        case 3: return "builtin:forest?instances=40";
        default: return "builtin:showcase";
    }
}

inline RtCoreConfig gpuGoldenConfig(int which) {
    RtCoreConfig c;
    c.gpu.cores = 8;
    c.l2.mode = L2Mode::Cache;
    if (which == 1) {
        c.scheduler.policy = "treeletPrefetch";
        c.cache.sizeBytes = 4096;
        c.l2.sizeBytes = 65536;
        c.l2.banks = 4;
        c.l2.ways = 4;
        c.dram.channels = 2;
        c.stack.shortStackEntries = 2;
        c.stack.refillEntries = 1;
    } else if (which == 2) {
        c.gpu.dispatch = WarpDispatch::Contiguous;
        c.scheduler.policy = "oldestFirst";
        c.cache.hitLatency = 400;
        c.memory.latency = 20;
        c.l2.hitLatency = 4;
        c.l2.bankCycles = 2;
    } else if (which == 3) {
        c.l2.mode = L2Mode::Ideal;
        c.scheduler.policy = "treelet";
    } else if (which == 4) {
        c.gpu.cores = 3;
        c.core.warpWidth = 8;
        c.core.inputQueueRays = 16;
        c.core.raySlots = 16;
        c.core.completionQueueRays = 2;
        c.core.completionPerCycle = 1;
        c.scheduler.issueWidth = 1;
        c.traversal.units = 1;
        c.memory.bytesPerCycle = 8;
        c.cache.sizeBytes = 2048;
        c.cache.ways = 2;
    }
    return c;
}

struct GpuGoldenScene {
    MicroScene scene;
    std::vector<SimRay> rays;
};

inline void loadGpuGoldenScene(GpuGoldenScene& g, int which, const RtCoreConfig& config) {
    loadScene(g.scene, gpuGoldenSource(which), config.bvh);
    g.rays = primaryRays(g.scene.snapshot.camera, 64, 48);
    for (std::size_t i = 0; i < g.rays.size(); ++i) g.rays[i].rayType = static_cast<std::uint32_t>(i % 2);
    std::vector<ModelHit> hits(g.rays.size());
    for (std::size_t i = 0; i < g.rays.size(); ++i) {
        TraversalCounters work;
        hits[i] = traceClosestHit(*g.scene.model, g.rays[i].ray, work);
    }
    const std::vector<SimRay> bounce = diffuseBounceRays(g.scene.snapshot, g.rays, hits, 2);
    g.rays.insert(g.rays.end(), bounce.begin(), bounce.end());
}

// Runs the workload's rays through `core` with `side`; the digests of the result.
inline GoldenRun gpuGoldenRun(RtCore& core, const std::vector<SimRay>& rays, ProgrammableSide& side,
                              std::vector<SimRayResult>* resultsOut = nullptr) {
    std::vector<SimRayResult> results(rays.size());
    for (std::size_t first = 0; first < rays.size(); first += 1000) {
        const std::size_t n = std::min<std::size_t>(1000, rays.size() - first);
        core.run(std::span(rays).subspan(first, n), side, std::span(results).subspan(first, n));
    }
    GoldenRun g;
    g.cycles = core.cycle();
    std::uint64_t h = 14695981039346656037ull;
    for (const SimRayResult& r : results) {
        const std::uint32_t v[6] = {r.cycles,       r.slotCycles,        r.stackSpills,
                                    r.stackRefills, r.hit.hit ? 1u : 0u, r.work.steps};
        h = fnv1a(h, v, sizeof v);
        h = fnv1a(h, &r.hit.t, sizeof r.hit.t);
    }
    g.rayDigest = h;
    // The whole tree: per core, l2, dram, config (less the launch parameters,
    // added after the goldens and unread by RtCore::run; cache.sectorBytes,
    // added after them and 0 here: unsectored, as the goldens' model; and
    // l2.serviceOrder, added after them and made here, the goldens' order).
    nlohmann::json tree = core.statsJson();
    for (nlohmann::json* config : {&tree["config"]}) {
        if (!config->is_object()) continue;
        (*config)["gpu"].erase("launch");
        (*config)["gpu"].erase("residentWarps");
        (*config)["shader"].erase("nextTraceLatency");
        if ((*config)["cache"]["sectorBytes"] == 0) (*config)["cache"].erase("sectorBytes");
        if ((*config)["l2"]["serviceOrder"] == "made") (*config)["l2"].erase("serviceOrder");  // added after them
    }
    const std::string dump = tree.dump();
    g.statsDigest = fnv1a(14695981039346656037ull, dump.data(), dump.size());
    if (resultsOut) *resultsOut = std::move(results);
    return g;
}

}  // namespace rtlab::rtcore_sim::test_support
