// Launches (docs/rtcore-model.md, "Launches"): hand-computed cycles of tiny
// launches, and the laws of the stats tree on a launch of a builtin scene.
#include "rtcore_invariants.hpp"
#include "rtcore_timing_helpers.hpp"

#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>

#include <gtest/gtest.h>

#include <vector>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using namespace rtlab::rtcore_sim::test_support;

namespace {

const ModelRay kDownOntoTriangle = makeModelRay(vec3(0.25f, 0.25f, 1.f), vec3(0.f, 0.f, -1.f));

// The one-triangle scene's ray alone on an idle core: three steps, each
// fetching one line (cold: its transfer slot and the memory latency; warm:
// the cache's hit latency), then the transform and triangle units.
std::uint64_t coldCycles(const RtCoreConfig& c) {
    const std::uint64_t miss =
        (c.cache.lineBytes + c.memory.bytesPerCycle - 1) / c.memory.bytesPerCycle + c.memory.latency;
    return 3 * miss + c.transform.latency + c.triangle.latency;
}
std::uint64_t warmCycles(const RtCoreConfig& c) {
    return 3 * std::uint64_t(c.cache.hitLatency) + c.transform.latency + c.triangle.latency;
}

struct LaunchRun {
    std::vector<SimRayResult> results;
    std::uint64_t cycles = 0;
    nlohmann::json stats;
};

LaunchRun runLaunch(const RtCoreConfig& config, const std::vector<SimRay>& rays,
                    const std::vector<std::uint32_t>& threads, std::uint32_t threadCount) {
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    OpaqueSide side;
    LaunchRun run;
    run.results.resize(rays.size());
    core.runLaunch(rays, threads, threadCount, side, run.results);
    run.cycles = core.cycle();
    run.stats = core.statsJson();
    return run;
}

}  // namespace

TEST(RtCoreLaunch, ChildStartsAfterItsParentPlusShaderLatency) {
    // Thread 0 traces A, then (from A's closest-hit shader) B, the same ray:
    //   A: submitted at 0, returns at coldCycles
    //   B: its group is ready nextTraceLatency cycles later; its lines are
    //      in the cache now, so it takes warmCycles
    // launch = coldCycles + nextTraceLatency + warmCycles
    RtCoreConfig config;
    config.shader.nextTraceLatency = 37;
    const LaunchRun run = runLaunch(config, {simRay(kDownOntoTriangle), simRay(kDownOntoTriangle, 1)}, {0, 0}, 1);
    EXPECT_EQ(run.results[0].cycles, coldCycles(config));
    EXPECT_EQ(run.results[1].cycles, warmCycles(config));  // latency counts from its own submission
    EXPECT_EQ(run.cycles, coldCycles(config) + 37 + warmCycles(config));
    EXPECT_EQ(coldCycles(config) + 37 + warmCycles(config), 3u * (2 + 200) + 4 + 8 + 37 + 3 * 4 + 4 + 8);
    ASSERT_TRUE(run.results[1].hit.hit);
    EXPECT_EQ(run.results[1].hit.t, 3.f);
    EXPECT_EQ(run.stats["rays"]["completed"], 2);
    EXPECT_EQ(run.stats["submission"]["warps"], 2);  // two TraceRay instructions of one warp

    // Without a shader latency the child is submitted in the cycle its parent returns.
    config.shader.nextTraceLatency = 0;
    EXPECT_EQ(runLaunch(config, {simRay(kDownOntoTriangle), simRay(kDownOntoTriangle)}, {0, 0}, 1).cycles,
              coldCycles(config) + warmCycles(config));
}

TEST(RtCoreLaunch, TwoIndependentRaysOnTwoCoresRunSideBySide) {
    // Threads 0 and 32 are in warps 0 and 1; round robin puts them on cores
    // 0 and 1, each with its own cache and port (l2 ideal): both rays take
    // coldCycles, and so does the launch.
    RtCoreConfig config;
    config.gpu.cores = 2;
    const std::vector<SimRay> rays = {simRay(kDownOntoTriangle), simRay(kDownOntoTriangle)};
    const LaunchRun two = runLaunch(config, rays, {0, 32}, 64);
    EXPECT_EQ(two.results[0].cycles, coldCycles(config));
    EXPECT_EQ(two.results[1].cycles, coldCycles(config));
    EXPECT_EQ(two.cycles, coldCycles(config));
    EXPECT_EQ(two.stats["memory"]["reads"], 6);  // each core misses its three lines

    // On one core the second warp is submitted a cycle later and its fetches
    // find the first's lines pending: three reads, and it is back no later.
    config.gpu.cores = 1;
    const LaunchRun one = runLaunch(config, rays, {0, 32}, 64);
    EXPECT_EQ(one.stats["memory"]["reads"], 3);
    EXPECT_EQ(one.cycles, coldCycles(config));
}

TEST(RtCoreLaunch, ResidentWarpsBoundWhatIsInFlight) {
    // One core with one resident warp: warp 1 becomes resident when warp 0
    // has left, in the cycle of warp 0's last result, and finds the lines in
    // the cache: launch = coldCycles + warmCycles (no shader latency: a new
    // warp's first TraceRay is ready at once).
    RtCoreConfig config;
    config.gpu.residentWarps = 1;
    const std::vector<SimRay> rays = {simRay(kDownOntoTriangle), simRay(kDownOntoTriangle)};
    const LaunchRun run = runLaunch(config, rays, {0, 32}, 64);
    EXPECT_EQ(run.cycles, coldCycles(config) + warmCycles(config));
    EXPECT_EQ(run.results[1].cycles, warmCycles(config));
}

TEST(RtCoreLaunch, BadLaunchesAreRefused) {
    RtCoreConfig config;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    OpaqueSide side;
    std::vector<SimRayResult> results(1);
    const std::vector<SimRay> rays = {simRay(kDownOntoTriangle)};
    const std::vector<std::uint32_t> tooFar = {4};
    EXPECT_THROW(core.runLaunch(rays, tooFar, 4, side, results), std::invalid_argument);
    const std::vector<std::uint32_t> thread0 = {0};
    EXPECT_THROW(core.runLaunch(rays, thread0, kMaxLaunchThreads + 1u, side, results), InputError);
}

TEST(RtCoreLaunch, ReorderingTheInputQueuesKeepsHitsAndWorkAndChangesTheOrder) {
    // gpu.rayOrder directionOrigin at launch level: each core admits the rays
    // waiting in its input queue in key order. Showcase's primary rays, each
    // pixel then tracing a ray of the opposite direction (another octant):
    // hits and per-ray work stay, the admission order (and so latencies) moves.
    RtCoreConfig config;
    MicroScene scene;
    loadScene(scene, "builtin:showcase", config.bvh);
    const std::vector<SimRay> primary = primaryRays(scene.snapshot.camera, 32, 24);
    std::vector<SimRay> rays = primary;
    std::vector<std::uint32_t> threads;
    for (std::uint32_t t = 0; t < primary.size(); ++t) threads.push_back(t);
    for (std::uint32_t t = 0; t < primary.size(); ++t) {
        SimRay back = primary[t];
        back.ray.direction = -back.ray.direction;
        rays.push_back(back);
        threads.push_back(t);
    }
    const auto run = [&](RayOrder order) {
        RtCoreConfig c = config;
        c.gpu.rayOrder = order;
        c.gpu.residentWarps = 8;
        RtCore core(c, *scene.model);
        OpaqueSide side;
        std::vector<SimRayResult> results(rays.size());
        core.runLaunch(rays, threads, static_cast<std::uint32_t>(primary.size()), side, results);
        return results;
    };
    const std::vector<SimRayResult> plain = run(RayOrder::Submission), sorted = run(RayOrder::DirectionOrigin);
    bool someLatencyDiffers = false;
    for (std::size_t i = 0; i < rays.size(); ++i) {
        ASSERT_EQ(plain[i].hit.hit, sorted[i].hit.hit) << i;
        ASSERT_EQ(plain[i].hit.t, sorted[i].hit.t) << i;
        ASSERT_EQ(plain[i].work.steps, sorted[i].work.steps) << i;
        someLatencyDiffers = someLatencyDiffers || plain[i].cycles != sorted[i].cycles;
    }
    EXPECT_TRUE(someLatencyDiffers);
}

TEST(RtCoreLaunch, LawsHoldOnALaunchOfABuiltinScene) {
    // Showcase's primary rays, each pixel a thread that then traces a second
    // ray (ray type 1) back towards the camera: a launch of two groups per
    // warp on four cores with a modelled L2, few resident warps, and the
    // serial and host-parallel simulations.
    for (const bool stressed : {false, true}) {
        RtCoreConfig config;
        config.gpu.cores = 4;
        config.l2.mode = L2Mode::Cache;
        config.gpu.residentWarps = stressed ? 2 : 16;
        if (stressed) {
            config.core.inputQueueRays = 32;
            config.core.completionQueueRays = 4;
            config.core.raySlots = 16;
            config.gpu.rayOrder = RayOrder::DirectionOrigin;  // input queues admit in key order
        }
        MicroScene scene;
        loadScene(scene, "builtin:showcase", config.bvh);
        const std::vector<SimRay> primary = primaryRays(scene.snapshot.camera, 64, 48);
        std::vector<SimRay> rays;
        std::vector<std::uint32_t> threads;
        for (std::uint32_t t = 0; t < primary.size(); ++t) {
            rays.push_back(primary[t]);
            threads.push_back(t);
        }
        for (std::uint32_t t = 0; t < primary.size(); t += 3) {  // every third thread traces a second ray
            SimRay back = primary[t];
            back.ray.direction = -back.ray.direction;
            back.rayType = 1;
            rays.push_back(back);
            threads.push_back(t);
        }
        RtCore core(config, *scene.model);
        OpaqueSide side;
        std::vector<SimRayResult> results(rays.size());
        core.runLaunch(rays, threads, static_cast<std::uint32_t>(primary.size()), side, results);
        const nlohmann::json stats = core.statsJson();
        SCOPED_TRACE(stressed ? "stressed" : "default");
        expectInvariants(stats, config);
        // Every unit, port, ray-slot pool, L2 bank and DRAM channel: its work
        // fits in the launch's cycles (utilization <= 1: cycles >= the
        // bottleneck's work), and DRAM moves at most its peak bytes per cycle.
        const double cycles = double(core.cycle());
        for (const ResourceUse& u : core.resourceUse()) {
            EXPECT_GE(u.busy, 0.0) << u.kind << " " << u.index;
            EXPECT_LE(u.busy, u.capacity * cycles) << u.kind << " " << u.index;
        }
        EXPECT_LE(stats["dram"]["bytesPerCycle"].get<double>(), stats["dram"]["peakBytesPerCycle"].get<double>());
        EXPECT_GT(stats["dram"]["readBytes"].get<double>(), 0.0);
        EXPECT_EQ(stats["rays"]["completed"], rays.size());
        for (std::size_t i = 0; i < rays.size(); ++i) {
            TraversalCounters work;
            OpaqueSide functional;
            const ModelHit h = traceRay(*scene.model, rays[i], functional, 0, work);
            ASSERT_EQ(h.hit, results[i].hit.hit) << i;
            ASSERT_EQ(h.t, results[i].hit.t) << i;
            ASSERT_EQ(work.steps, results[i].work.steps) << i;
        }
        // The same launch without per-ray results: the same cycles and statistics.
        RtCore without(config, *scene.model);
        without.runLaunch(rays, threads, static_cast<std::uint32_t>(primary.size()), side, {});
        EXPECT_EQ(without.cycle(), core.cycle());
        EXPECT_EQ(without.statsJson(), stats);
    }
}

TEST(RtCoreLaunch, AnAbortedInnerScopeDropsTheLaunchAndLeavesTheBackEndUsable) {
    // An exception leaves an inner launch scope (abort) while the outer one
    // is still open: the outer scope's end drops the launch (its log may be
    // half built) instead of simulating it or failing; the next launch runs.
    RtCoreConfig config;
    RtCoreBackend backend(config);
    backend.beginLaunch(64, "outer");
    backend.beginLaunch(64, "inner");
    backend.abortLaunch();
    EXPECT_NO_THROW(backend.endLaunch());
    EXPECT_TRUE(backend.launches().empty());
    backend.beginLaunch(64, "next");
    EXPECT_NO_THROW(backend.endLaunch());
    EXPECT_THROW(backend.endLaunch(), std::logic_error);  // no launch open
    // More threads than the model takes are refused.
    EXPECT_THROW(backend.beginLaunch(kMaxLaunchThreads + 1u, "huge"), tracer::PipelineError);
    EXPECT_THROW(backend.endLaunch(), std::logic_error);  // the refused launch was never opened
}
