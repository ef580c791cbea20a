// Invariants of the timing model on real scenes: resource bounds,
// utilizations, conservation of rays, the latency breakdown adding up, and
// determinism across runs and thread limits.
#include "rtcore_invariants.hpp"
#include "rtcore_timing_helpers.hpp"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using namespace rtlab::rtcore_sim::test_support;
using nlohmann::json;

namespace {

// Showcase primary rays (two ray types) in a few batches; returns the stats.
json runShowcase(const RtCoreConfig& config, std::vector<SimRayResult>* resultsOut = nullptr, bool everyCycle = false) {
    MicroScene scene;
    loadScene(scene, "builtin:showcase", config.bvh);
    std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 80, 60);
    for (std::size_t i = 0; i < rays.size(); ++i) rays[i].rayType = static_cast<std::uint32_t>(i % 2);
    RtCore core(config, *scene.model);
    core.simulateEveryCycle(everyCycle);
    std::vector<SimRayResult> results(rays.size());
    OpaqueSide side;
    for (std::size_t first = 0; first < rays.size(); first += 1000) {
        const std::size_t n = std::min<std::size_t>(1000, rays.size() - first);
        core.run(std::span(rays).subspan(first, n), side, std::span(results).subspan(first, n));
    }
    if (resultsOut) *resultsOut = results;
    return core.statsJson();
}

}  // namespace

TEST(RtCoreInvariants, HoldForDefaultAndStressedConfigurations) {
    RtCoreConfig defaults;
    expectInvariants(runShowcase(defaults), defaults);

    // Everything scarce: queues, slots, units, bandwidth, short stack, cache.
    RtCoreConfig scarce;
    scarce.core.warpWidth = 8;
    scarce.core.inputQueueRays = 8;
    scarce.core.raySlots = 16;
    scarce.core.completionQueueRays = 2;
    scarce.core.completionPerCycle = 1;
    scarce.scheduler.issueWidth = 1;
    scarce.traversal.units = 1;
    scarce.traversal.boxesPerCycle = 2;
    scarce.triangle.units = 1;
    scarce.stack.shortStackEntries = 2;
    scarce.stack.refillEntries = 1;
    scarce.cache.sizeBytes = 2048;
    scarce.cache.ways = 2;
    scarce.memory.bytesPerCycle = 4;
    scarce.scheduler.policy = "treelet";
    const json s = runShowcase(scarce);
    expectInvariants(s, scarce);
    EXPECT_GT(s["stack"]["spilledEntries"].get<std::uint64_t>(), 0u);
    EXPECT_GT(s["stack"]["refills"].get<std::uint64_t>(), 0u);
    EXPECT_GT(s["stalls"]["blockedCycles"]["inputQueueFull"].get<std::uint64_t>(), 0u);
    EXPECT_GT(s["stalls"]["blockedCycles"]["noFreeRaySlot"].get<std::uint64_t>(), 0u);
    EXPECT_GT(s["stalls"]["rayCycles"]["boxUnitBusy"].get<std::uint64_t>(), 0u);
    EXPECT_GT(s["memory"]["queueCycles"].get<std::uint64_t>(), 0u);
}

TEST(RtCoreInvariants, IdenticalAcrossRunsAndThreadLimits) {
    RtCoreConfig config;
    config.scheduler.policy = "treelet";
    std::vector<SimRayResult> first, second, third;
    const json a = runShowcase(config, &first);
    const json b = runShowcase(config, &second);
    // The whole pipeline (BVH build, simulation) inside a 4-thread arena and under a 1-thread TBB limit.
    json d;
    tbb::task_arena arena(4);
    arena.execute([&] { d = runShowcase(config); });
    json c;
    {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
        c = runShowcase(config, &third);
    }
    EXPECT_EQ(a, b);
    EXPECT_EQ(a, c);
    EXPECT_EQ(a, d);
    ASSERT_EQ(first.size(), second.size());
    for (std::size_t i = 0; i < first.size(); ++i) {
        ASSERT_EQ(first[i].cycles, second[i].cycles) << i;
        ASSERT_EQ(first[i].cycles, third[i].cycles) << i;
        ASSERT_TRUE(sameHit(first[i].hit, third[i].hit)) << i;
    }
}

TEST(RtCoreInvariants, SkippingIdleCyclesChangesNothing) {
    // The event-driven loop jumps over cycles in which nothing can happen;
    // visiting every cycle must give the same results and statistics.
    RtCoreConfig scarce;
    scarce.core.warpWidth = 8;
    scarce.core.inputQueueRays = 8;
    scarce.core.raySlots = 16;
    scarce.core.completionQueueRays = 2;
    scarce.core.completionPerCycle = 1;
    scarce.stack.shortStackEntries = 2;
    scarce.stack.refillEntries = 1;
    scarce.memory.bytesPerCycle = 4;
    for (const RtCoreConfig& config : {RtCoreConfig{}, scarce}) {
        std::vector<SimRayResult> skipping, everyCycle;
        const json a = runShowcase(config, &skipping, false);
        const json b = runShowcase(config, &everyCycle, true);
        EXPECT_EQ(a, b);
        for (std::size_t i = 0; i < skipping.size(); ++i) ASSERT_EQ(skipping[i].cycles, everyCycle[i].cycles) << i;
    }
}

TEST(RtCoreInvariants, ConfigurationErrorsAndMismatchedScenes) {
    RtCoreConfig config;
    config.core.warpWidth = 64;
    config.core.inputQueueRays = 32;
    EXPECT_THROW(config.validate("cfg"), InputError);
    config.core.inputQueueRays = 64;
    config.cache.sizeBytes = 3 * 64 * 4;  // 3 sets
    EXPECT_THROW(config.validate("cfg"), InputError);
    config.cache.sizeBytes = 4096;
    config.stack.refillEntries = 9;
    EXPECT_THROW(config.validate("cfg"), InputError);
    config.stack.refillEntries = 4;
    EXPECT_NO_THROW(config.validate("cfg"));

    MicroScene scene;
    makeOneTriangleScene(scene, BvhParams{});
    RtCoreConfig other;
    other.bvh.width = 4;  // the scene was built with width 6
    EXPECT_THROW(RtCore(other, *scene.model), std::invalid_argument);
    RtCoreConfig bad;
    bad.core.inputQueueRays = 1;
    EXPECT_THROW(RtCore(bad, *scene.model), InputError);

    // Empty batches and empty scenes.
    RtCore core(RtCoreConfig{}, *scene.model);
    EXPECT_NO_THROW(runBatch(core, {}));
    EXPECT_EQ(core.cycle(), 0u);
    MicroScene empty;
    empty.world.addMaterial({});
    empty.build(BvhParams{});
    RtCore emptyCore(RtCoreConfig{}, *empty.model);
    const auto results =
        runBatch(emptyCore, std::vector<SimRay>(3, simRay(makeModelRay(vec3(0.f), vec3(0.f, 0.f, -1.f)))));
    for (const auto& r : results) {
        EXPECT_FALSE(r.hit.hit);
        EXPECT_EQ(r.work.steps, 0u);
    }
    EXPECT_EQ(emptyCore.statsJson()["rays"]["completed"], 3);
}

TEST(RtCoreInvariants, ResetStatsStartsAFrameAndResetGoesCold) {
    RtCoreConfig config;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    const SimRay ray = simRay(makeModelRay(vec3(0.25f, 0.25f, 1.f), vec3(0.f, 0.f, -1.f)));
    const std::uint32_t cold = runBatch(core, {ray})[0].cycles;
    runBatch(core, {ray});
    EXPECT_EQ(core.statsJson()["frame"]["batches"], 2);
    core.resetStats();
    EXPECT_EQ(core.statsJson()["frame"]["cycles"], 0);
    EXPECT_EQ(core.statsJson()["rays"]["completed"], 0);
    core.reset();
    EXPECT_EQ(core.cycle(), 0u);
    EXPECT_EQ(runBatch(core, {ray})[0].cycles, cold);
}

TEST(RtCoreInvariants, ASideThatThrowsLeavesTheCoreUsable) {
    struct ThrowingSide final : ProgrammableSide {
        int calls = 0;
        CandidateVerdict triangle(std::uint32_t, const TriangleCandidate&) override {
            if (++calls == 10) throw std::runtime_error("shader failed");
            return {};
        }
        ProceduralVerdict procedural(std::uint32_t, const ProceduralCandidate&) override { return {}; }
    };
    RtCoreConfig config;
    MicroScene scene;
    loadScene(scene, "builtin:cornell", config.bvh);
    const std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 16, 16);
    RtCore core(config, *scene.model);
    ThrowingSide side;
    std::vector<SimRayResult> results(rays.size());
    EXPECT_THROW(core.run(rays, side, results), std::runtime_error);
    const std::uint64_t reached = core.cycle();
    EXPECT_GT(reached, 0u);
    // The next batch runs normally from there and finds the functional hits.
    const std::vector<SimRayResult> again = runBatch(core, rays);
    EXPECT_GT(core.cycle(), reached);
    for (std::size_t i = 0; i < rays.size(); ++i) {
        TraversalCounters work;
        ASSERT_TRUE(sameHit(again[i].hit, traceClosestHit(*scene.model, rays[i].ray, work))) << i;
    }
}
