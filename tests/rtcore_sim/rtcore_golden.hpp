#pragma once
// Workloads and a digest for the single-core reproduction test
// (test_rtcore_gpu.cpp, RtCoreGpu.OneCoreWithIdealL2ReproducesTheSingleCoreModel):
// the digests in that test were computed by this very code linked against
// the single-core model as it was before the GPU level (commit 13d931e), so
// the test fails if one core with an ideal L2 changes any cycle or statistic.
#include "rtcore_timing_helpers.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim::test_support {

inline std::uint64_t fnv1a(std::uint64_t h, const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

// The stats tree without what the GPU level added (and without the config echo).
inline nlohmann::json singleCoreView(nlohmann::json s) {
    for (const char* key : {"config", "gpu", "l2", "dram", "cores"}) s.erase(key);
    if (s.contains("rays") && s["rays"].contains("latencyBreakdown"))
        for (const char* key : {"l2", "dram"}) s["rays"]["latencyBreakdown"].erase(key);
    return s;
}

struct GoldenRun {
    std::uint64_t cycles = 0;       // the core's clock after the run
    std::uint64_t rayDigest = 0;    // per-ray cycles, slot cycles, spills, refills, hit t
    std::uint64_t statsDigest = 0;  // singleCoreView(statsJson()).dump()
};

// Workload `which`: 0 showcase defaults, 1 showcase scarce, 2 showcase treelet + 8 KB cache,
// 3 cornell oldestFirst with 2 ray types. Primary rays 80x60 in batches of 1000.
inline RtCoreConfig goldenConfig(int which) {
    RtCoreConfig c;
    if (which == 1) {
        c.core.warpWidth = 8;
        c.core.inputQueueRays = 8;
        c.core.raySlots = 16;
        c.core.completionQueueRays = 2;
        c.core.completionPerCycle = 1;
        c.scheduler.issueWidth = 1;
        c.traversal.units = 1;
        c.traversal.boxesPerCycle = 2;
        c.triangle.units = 1;
        c.stack.shortStackEntries = 2;
        c.stack.refillEntries = 1;
        c.cache.sizeBytes = 2048;
        c.cache.ways = 2;
        c.memory.bytesPerCycle = 4;
    } else if (which == 2) {
        c.scheduler.policy = "treelet";
        c.cache.sizeBytes = 8192;
    } else if (which == 3) {
        c.scheduler.policy = "oldestFirst";
        c.memory.latency = 150;
    }
    return c;
}

inline GoldenRun goldenRun(int which, const RtCoreConfig& config) {
    MicroScene scene;
    loadScene(scene, which == 3 ? "builtin:cornell" : "builtin:showcase", config.bvh);
    std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 80, 60);
    for (std::size_t i = 0; i < rays.size(); ++i) rays[i].rayType = static_cast<std::uint32_t>(i % 2);
    RtCore core(config, *scene.model);
    std::vector<SimRayResult> results(rays.size());
    OpaqueSide side;
    for (std::size_t first = 0; first < rays.size(); first += 1000) {
        const std::size_t n = std::min<std::size_t>(1000, rays.size() - first);
        core.run(std::span(rays).subspan(first, n), side, std::span(results).subspan(first, n));
    }
    GoldenRun g;
    g.cycles = core.cycle();
    std::uint64_t h = 14695981039346656037ull;
    for (const SimRayResult& r : results) {
        const std::uint32_t v[5] = {r.cycles, r.slotCycles, r.stackSpills, r.stackRefills, r.hit.hit ? 1u : 0u};
        h = fnv1a(h, v, sizeof v);
        h = fnv1a(h, &r.hit.t, sizeof r.hit.t);
    }
    g.rayDigest = h;
    const std::string dump = singleCoreView(core.statsJson()).dump();
    g.statsDigest = fnv1a(14695981039346656037ull, dump.data(), dump.size());
    return g;
}

}  // namespace rtlab::rtcore_sim::test_support
