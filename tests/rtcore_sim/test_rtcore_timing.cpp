// Hand-computed cycle counts of the timing model on micro scenes. Every
// expected value is the formula of docs/rtcore-model.md ("Following one ray
// by hand"), written with the configuration's parameters, not a number copied
// from a run.
#include "rtcore_timing_helpers.hpp"

#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>

#include <gtest/gtest.h>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using namespace rtlab::rtcore_sim::test_support;

namespace {

// Cycles a cold miss of one line takes: its transfer slot, then the memory latency.
std::uint64_t missCycles(const RtCoreConfig& c) {
    return (c.cache.lineBytes + c.memory.bytesPerCycle - 1) / c.memory.bytesPerCycle + c.memory.latency;
}
std::uint64_t transferCycles(const RtCoreConfig& c) {
    return (c.cache.lineBytes + c.memory.bytesPerCycle - 1) / c.memory.bytesPerCycle;
}

const ModelRay kDownOntoTriangle = makeModelRay(vec3(0.25f, 0.25f, 1.f), vec3(0.f, 0.f, -1.f));

}  // namespace

TEST(RtCoreTiming, OneTriangleColdCache) {
    // One ray, three steps, each fetching one line that misses:
    //   TLAS leaf (12 bytes at the TLAS base)       miss
    //   instance descriptor (64 bytes at 4096)      miss, then the transform unit
    //   BLAS leaf (8 + 44 bytes at 8192)            miss, then one triangle test
    // cycles = 3 x (ceil(lineBytes / bytesPerCycle) + memory.latency) + transform.latency + triangle.latency
    const RtCoreConfig config;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    const auto results = runBatch(core, {simRay(kDownOntoTriangle)});

    const std::uint64_t expected = 3 * missCycles(config) + config.transform.latency + config.triangle.latency;
    EXPECT_EQ(expected, 3u * (2 + 200) + 4 + 8);  // the default parameters, as in the doc
    ASSERT_TRUE(results[0].hit.hit);
    EXPECT_EQ(results[0].hit.t, 3.f);
    EXPECT_EQ(results[0].cycles, expected);
    EXPECT_EQ(core.cycle(), expected);
    EXPECT_EQ(results[0].work.steps, 3u);

    const auto stats = core.statsJson();
    EXPECT_EQ(stats["frame"]["cycles"], expected);
    EXPECT_EQ(stats["cache"]["accesses"], 3);
    EXPECT_EQ(stats["cache"]["misses"], 3);
    EXPECT_EQ(stats["memory"]["readBytes"], 3 * config.cache.lineBytes);
    EXPECT_EQ(stats["transformUnits"]["busyCycles"], 1);
    EXPECT_EQ(stats["triangleUnits"]["busyCycles"], 1);
    EXPECT_EQ(stats["traversalUnits"]["busyCycles"], 0);
    EXPECT_EQ(stats["rays"]["latencyBreakdown"]["fetch"], 3 * missCycles(config));
    EXPECT_EQ(stats["stalls"]["rayCycles"]["cacheMissAndMemory"], 3 * (missCycles(config) - config.cache.hitLatency));
}

TEST(RtCoreTiming, SameRayTwiceHitsInTheNodeCache) {
    // The second run finds the three lines in the cache:
    // cycles = 3 x cache.hitLatency + transform.latency + triangle.latency.
    RtCoreConfig config;
    config.cache.hitLatency = 3;
    config.transform.latency = 5;
    config.triangle.latency = 7;
    config.memory.latency = 100;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    const auto cold = runBatch(core, {simRay(kDownOntoTriangle)});
    const std::uint64_t afterCold = core.cycle();
    core.resetStats();
    const auto warm = runBatch(core, {simRay(kDownOntoTriangle)});

    const std::uint64_t coldCycles = 3 * missCycles(config) + config.transform.latency + config.triangle.latency;
    const std::uint64_t warmCycles = 3 * config.cache.hitLatency + config.transform.latency + config.triangle.latency;
    EXPECT_EQ(cold[0].cycles, coldCycles);
    EXPECT_EQ(warm[0].cycles, warmCycles);
    EXPECT_EQ(core.cycle(), afterCold + warmCycles);  // the clock continues across batches
    EXPECT_TRUE(sameHit(cold[0].hit, warm[0].hit));
    const auto stats = core.statsJson();  // the second batch only (resetStats)
    EXPECT_EQ(stats["frame"]["cycles"], warmCycles);
    EXPECT_EQ(stats["cache"]["hits"], 3);
    EXPECT_EQ(stats["cache"]["misses"], 0);
    EXPECT_EQ(stats["memory"]["reads"], 0);

    // A scene update invalidates the cache: cold again.
    scene.model->update(ecs::makeSnapshot(scene.world, scene.world.update(0.f)));
    EXPECT_EQ(runBatch(core, {simRay(kDownOntoTriangle)})[0].cycles, coldCycles);
}

TEST(RtCoreTiming, TwoLevelInstanceWithNodesAtBothLevels) {
    // Two instances A (z = -2) and B (z = -10) of a mesh of two triangles far
    // apart in x; width 2 and one primitive per leaf, so both levels have a
    // root node with two leaves. Layout: TLAS node (72 bytes, lines 0-1) and
    // its leaves (at 72 and 84, line 1); instance table at 4096; the BLAS at
    // 8192: node 8192-8263 (lines 128-129), leaf 0 at 8264-8315 (line 129).
    // The ray goes down onto the triangle of BLAS leaf 0 inside A:
    //   TLAS node      2 misses back to back: T + (T + L); box test        -> both instances' boxes hit, B pushed
    //   TLAS leaf A    line 1, already there: hit
    //   instance A     miss (T + L); transform
    //   BLAS node      2 misses (lines 128, 129): T + (T + L); box test    -> one child hit
    //   BLAS leaf 0    line 129: hit; one triangle test                    -> commit t = 3
    //   then B's TLAS leaf is popped and culled (entry t = 11 > 3): finished.
    // cycles = 2 (T + T + L) + 2 box + 2 hit + (T + L) + transform + triangle
    RtCoreConfig config;
    config.bvh.width = 2;
    config.bvh.maxLeafSize = 1;
    config.bvh.tlasMaxLeafSize = 1;
    MicroScene scene;
    scene.world.addMaterial({});
    ecs::Geometry g = oneTriangleGeometry(vec3(0.f), vec3(1.f, 0.f, 0.f), vec3(0.f, 1.f, 0.f));
    const ecs::Geometry far = oneTriangleGeometry(vec3(5.f, 0.f, 0.f), vec3(6.f, 0.f, 0.f), vec3(5.f, 1.f, 0.f));
    g.positions.insert(g.positions.end(), far.positions.begin(), far.positions.end());
    g.normals.insert(g.normals.end(), far.normals.begin(), far.normals.end());
    g.indices.insert(g.indices.end(), {3, 4, 5});
    const ecs::MeshId mesh = scene.world.addMesh(ecs::load::makeMesh("two", g));
    for (float z : {-2.f, -10.f}) {
        const ecs::Entity e = scene.world.create("inst");
        scene.world.emplace(e, ecs::LocalTransform{vec3(0.f, 0.f, z)});
        scene.world.emplace(e, ecs::MeshInstance{mesh});
    }
    scene.build(config.bvh);
    const ModelScene& model = *scene.model;

    // The structure the formula assumes.
    ASSERT_TRUE(model.tlas().root.isNode());
    ASSERT_EQ(model.tlas().nodes.size(), 1u);
    const Blas& blas = *model.blas(mesh);
    ASSERT_TRUE(blas.bvh.root.isNode());
    ASSERT_EQ(blas.bvh.nodes.size(), 1u);
    ASSERT_EQ(blas.bvh.leaves.size(), 2u);
    EXPECT_EQ(nodeBytes(2), 72u);
    // Aim at the triangle of BLAS leaf 0.
    const std::uint32_t target = blas.bvh.refs[blas.bvh.leaves[0].firstRef].primitive;
    const vec3 aim = target == 0 ? vec3(0.25f, 0.25f, 1.f) : vec3(5.25f, 0.25f, 1.f);

    RtCore core(config, model);
    const auto results = runBatch(core, {simRay(makeModelRay(aim, vec3(0.f, 0.f, -1.f)))});
    ASSERT_TRUE(results[0].hit.hit);
    EXPECT_EQ(results[0].hit.t, 3.f);
    EXPECT_EQ(results[0].hit.primitiveIndex, target);
    const auto& w = results[0].work;
    EXPECT_EQ(w.nodeVisits, 2u);
    EXPECT_EQ(w.leafVisits, 2u);
    EXPECT_EQ(w.instanceTransitions, 1u);
    EXPECT_EQ(w.triangleTests, 1u);

    const std::uint64_t T = transferCycles(config), L = config.memory.latency;
    const std::uint64_t expected = 2 * (T + T + L) + 2 * config.traversal.latency + 2 * config.cache.hitLatency +
                                   (T + L) + config.transform.latency + config.triangle.latency;
    EXPECT_EQ(expected, 638u);  // the defaults, as in the doc
    EXPECT_EQ(results[0].cycles, expected);
    const auto stats = core.statsJson();
    EXPECT_EQ(stats["cache"]["misses"], 5);
    EXPECT_EQ(stats["cache"]["hits"], 2);
    EXPECT_EQ(stats["stack"]["pushes"], 1);
    EXPECT_EQ(stats["stack"]["pops"], 1);
}

TEST(RtCoreTiming, FullInputQueueBlocksTheNextWarp) {
    // Warps of 4 rays, an input queue of 4 rays and one ray slot; 8 rays on a
    // warm cache, each taking L = 3 hit + transform + triangle cycles in the slot.
    // Warp 0 enters at s (the batch start); its rays run one after the other,
    // ray k finishing at s + (k+1) L. Warp 1 needs 4 free entries: it is
    // refused in cycles s+1 .. s+3L (ray 3 leaves the queue at s + 3L) and
    // enters at s + 3L + 1. Blocked cycles (input queue full) = (4 - 1) L.
    RtCoreConfig config;
    config.core.warpWidth = 4;
    config.core.inputQueueRays = 4;
    config.core.raySlots = 1;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    runBatch(core, {simRay(kDownOntoTriangle)});  // warm the cache
    core.resetStats();
    const std::uint64_t s = core.cycle();
    const auto results = runBatch(core, std::vector<SimRay>(8, simRay(kDownOntoTriangle)));

    const std::uint64_t L = 3 * config.cache.hitLatency + config.transform.latency + config.triangle.latency;
    const std::uint64_t W = config.core.warpWidth;
    for (std::uint32_t k = 0; k < 4; ++k) EXPECT_EQ(results[k].cycles, (k + 1) * L) << k;          // submitted at s
    for (std::uint32_t j = 0; j < 4; ++j) EXPECT_EQ(results[4 + j].cycles, (j + 2) * L - 1) << j;  // at s + 3L + 1
    EXPECT_EQ(core.cycle(), s + 8 * L);
    const auto stats = core.statsJson();
    EXPECT_EQ(stats["stalls"]["blockedCycles"]["inputQueueFull"], (W - 1) * L);
    EXPECT_EQ(stats["submission"]["blockedCycles"]["inputQueueFull"], (W - 1) * L);
    // Ray-cycles in the input queue: warp 0 waits 0, L, 2L, 3L; warp 1 waits L-1, 2L-1, 3L-1, 4L-1.
    EXPECT_EQ(stats["stalls"]["rayCycles"]["inputQueue"], 6 * L + 10 * L - 4);
    EXPECT_EQ(stats["rays"]["submitted"], 8);
    EXPECT_EQ(stats["rays"]["completed"], 8);
    EXPECT_EQ(stats["submission"]["inputQueue"]["occupancy"]["max"], 4);
    EXPECT_EQ(stats["stalls"]["blockedCycles"]["completionQueueFull"], 0);
}

TEST(RtCoreTiming, FullCompletionQueueKeepsFinishedRaysInTheirSlots) {
    // Four rays finish in the same cycle f (four transform and triangle
    // units: no contention); the completion queue holds one ray and returns one per
    // cycle. Ray 0 enters at f and is returned at f; ray k enters at f + k - 1
    // (after the delivery in that cycle) and is returned at f + k.
    // Blocked cycles (a finished ray waiting for an entry) = cycles f and f + 1
    // (rays 2, 3 and then ray 3 blocked) = 2.
    RtCoreConfig config;
    config.core.raySlots = 4;
    config.core.completionQueueRays = 1;
    config.core.completionPerCycle = 1;
    config.scheduler.issueWidth = 4;
    config.transform.units = 4;
    config.triangle.units = 4;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    runBatch(core, {simRay(kDownOntoTriangle)});  // warm the cache
    core.resetStats();
    const auto results = runBatch(core, std::vector<SimRay>(4, simRay(kDownOntoTriangle)));

    const std::uint64_t L = 3 * config.cache.hitLatency + config.transform.latency + config.triangle.latency;
    for (std::uint32_t k = 0; k < 4; ++k) EXPECT_EQ(results[k].cycles, L + k) << k;
    const auto stats = core.statsJson();
    EXPECT_EQ(stats["stalls"]["blockedCycles"]["completionQueueFull"], 2);
    EXPECT_EQ(stats["stalls"]["rayCycles"]["completionQueueFull"], 0 + 0 + 1 + 2);
    EXPECT_EQ(stats["stalls"]["rayCycles"]["completionQueue"], 0 + 1 + 1 + 1);
}

TEST(RtCoreTiming, UnitContentionDelaysTheSecondRay) {
    // Two identical rays issued in the same cycle on a warm cache with one
    // transform unit: the second waits one cycle for it (occupancy 1), and the
    // triangle units (2) take both at once. Ray 1 finishes one cycle later.
    RtCoreConfig config;
    config.scheduler.issueWidth = 2;
    config.transform.units = 1;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    runBatch(core, {simRay(kDownOntoTriangle)});
    core.resetStats();
    const auto results = runBatch(core, std::vector<SimRay>(2, simRay(kDownOntoTriangle)));
    const std::uint64_t L = 3 * config.cache.hitLatency + config.transform.latency + config.triangle.latency;
    EXPECT_EQ(results[0].cycles, L);
    EXPECT_EQ(results[1].cycles, L + 1);
    const auto stats = core.statsJson();
    EXPECT_EQ(stats["stalls"]["rayCycles"]["transformUnitBusy"], 1);
    EXPECT_EQ(stats["transformUnits"]["waitCycles"], 1);
}

TEST(RtCoreTiming, AnyHitShaderRoundTripIsCharged) {
    // A side that runs an any-hit shader for every candidate: one round trip
    // of shader.anyHitLatency after the triangle test.
    struct AnyHitSide final : ProgrammableSide {
        std::uint32_t calls = 0;
        CandidateVerdict triangle(std::uint32_t, const TriangleCandidate& c) override {
            ++calls;
            EXPECT_EQ(c.t, 3.f);
            EXPECT_EQ(c.u, 0.25f);
            EXPECT_EQ(c.v, 0.25f);
            EXPECT_EQ(c.objectGeometricNormal, vec3(0.f, 0.f, 1.f));
            return CandidateVerdict{true, false, true};
        }
        ProceduralVerdict procedural(std::uint32_t, const ProceduralCandidate&) override { return {}; }
    };
    RtCoreConfig config;
    config.shader.anyHitLatency = 37;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    AnyHitSide side;
    std::vector<SimRay> rays{simRay(kDownOntoTriangle)};
    std::vector<SimRayResult> results(1);
    core.run(rays, side, results);
    EXPECT_EQ(side.calls, 1u);
    EXPECT_EQ(results[0].cycles, 3 * missCycles(config) + config.transform.latency + config.triangle.latency +
                                     config.shader.anyHitLatency);
    EXPECT_EQ(results[0].work.anyHitCalls, 1u);
    EXPECT_EQ(core.statsJson()["shader"]["anyHitCalls"], 1);
}

TEST(RtCoreTiming, StackSpillsAndRefillsGoToMemory) {
    // A short stack of one entry: a TLAS leaf with three instances pushes two
    // (one stays on chip, one spills); popping them later refills from memory.
    RtCoreConfig config;
    config.bvh.tlasMaxLeafSize = 4;
    config.bvh.sahTraversalCost = 100.f;  // the builder keeps the three instances in one leaf
    config.stack.shortStackEntries = 1;
    config.stack.refillEntries = 1;
    MicroScene scene;
    scene.world.addMaterial({});
    const ecs::MeshId mesh = scene.world.addMesh(
        ecs::load::makeMesh("tri", oneTriangleGeometry(vec3(0.f), vec3(1.f, 0.f, 0.f), vec3(0.f, 1.f, 0.f))));
    for (float z : {-2.f, -2.5f, -3.f}) {  // three instances one behind the other
        const ecs::Entity e = scene.world.create("tri");
        scene.world.emplace(e, ecs::LocalTransform{vec3(0.f, 0.f, z)});
        scene.world.emplace(e, ecs::MeshInstance{mesh});
    }
    scene.build(config.bvh);
    ASSERT_TRUE(scene.model->tlas().root.isLeaf());  // one leaf of three instances
    RtCore core(config, *scene.model);
    // A ray beside the triangles (past the hypotenuse): no hit culls the instances left on the stack.
    const auto results = runBatch(core, {simRay(makeModelRay(vec3(0.75f, 0.75f, 1.f), vec3(0.f, 0.f, -1.f)))});
    EXPECT_FALSE(results[0].hit.hit);
    EXPECT_EQ(results[0].work.instanceTransitions, 3u);
    EXPECT_EQ(results[0].stackSpills, 1u);
    EXPECT_EQ(results[0].stackRefills, 1u);
    const auto stats = core.statsJson();
    EXPECT_EQ(stats["stack"]["spilledEntries"], 1);
    EXPECT_EQ(stats["stack"]["refills"], 1);
    EXPECT_EQ(stats["memory"]["writeBytes"], config.stack.entryBytes);
    // The refill is one read of entryBytes: ceil(8 / 32) + latency on the ray's path.
    EXPECT_EQ(stats["rays"]["latencyBreakdown"]["stackRefill"],
              (config.stack.entryBytes + config.memory.bytesPerCycle - 1) / config.memory.bytesPerCycle +
                  config.memory.latency);
}
