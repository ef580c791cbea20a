// The timed traversal produces exactly the functional traversal's hits and
// work counts (they share one step function), for every scheduling policy
// and BVH width; and the scheduling policy changes cycles, never hits.
#include "rtcore_timing_helpers.hpp"

#include <rtlab/rtcore_sim/scheduler.hpp>

#include <gtest/gtest.h>

#include <iostream>
#include <map>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using namespace rtlab::rtcore_sim::test_support;

namespace {

// One comparison of timed against functional traversal.
struct Comparison {
    std::string label;  // width and policy
    std::size_t rays = 0;
    std::uint64_t functionalHits = 0;
    std::uint64_t differentHits = 0;
    std::uint64_t differentWork = 0;
};

// Timed vs functional hits (and work) for `source`'s primary rays, for
// widths 2, 4, 8 and every scheduling policy.
std::vector<Comparison> compareTimedWithFunctional(const std::string& source) {
    std::vector<Comparison> out;
    for (std::uint32_t width : {2u, 4u, 8u}) {
        RtCoreConfig config;
        config.bvh.width = width;
        MicroScene scene;
        loadScene(scene, source, config.bvh);
        const std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 96, 72);
        std::vector<ModelHit> functional(rays.size());
        std::vector<TraversalCounters> work(rays.size());
        std::uint64_t hits = 0;
        for (std::size_t i = 0; i < rays.size(); ++i) {
            functional[i] = traceClosestHit(*scene.model, rays[i].ray, work[i]);
            hits += functional[i].hit;
        }
        for (const std::string& policy : schedulerPolicyNames()) {
            config.scheduler.policy = policy;
            RtCore core(config, *scene.model);
            const std::vector<SimRayResult> results = runBatch(core, rays);
            Comparison c{source + " width " + std::to_string(width) + " policy " + policy, rays.size(), hits, 0, 0};
            for (std::size_t i = 0; i < rays.size(); ++i) {
                c.differentHits += !sameHit(results[i].hit, functional[i]);
                c.differentWork += !sameWork(results[i].work, work[i]);
            }
            out.push_back(c);
        }
    }
    return out;
}

}  // namespace

TEST(RtCoreEquivalence, ShowcasePrimaryRaysEveryPolicyAndWidth) {
    const std::vector<Comparison> comparisons = compareTimedWithFunctional("builtin:showcase");
    ASSERT_EQ(comparisons.size(), 3 * schedulerPolicyNames().size());
    for (const Comparison& c : comparisons) {
        EXPECT_GT(c.functionalHits, c.rays / 2) << c.label;  // the rays see the scene
        EXPECT_EQ(c.differentHits, 0u) << c.label;
        EXPECT_EQ(c.differentWork, 0u) << c.label;
    }
}

TEST(RtCoreEquivalence, CornellPrimaryRaysEveryPolicyAndWidth) {
    const std::vector<Comparison> comparisons = compareTimedWithFunctional("builtin:cornell");
    ASSERT_EQ(comparisons.size(), 3 * schedulerPolicyNames().size());
    for (const Comparison& c : comparisons) {
        EXPECT_GT(c.functionalHits, c.rays / 2) << c.label;
        EXPECT_EQ(c.differentHits, 0u) << c.label;
        EXPECT_EQ(c.differentWork, 0u) << c.label;
    }
}

TEST(RtCoreEquivalence, PoliciesGiveTheSameHitsButDifferentCycles) {
    // A scheduler-bound configuration (one issue per cycle, many rays in
    // flight, a small cache): which ready ray issues next matters.
    RtCoreConfig config;
    config.scheduler.issueWidth = 1;
    config.core.raySlots = 256;
    config.core.inputQueueRays = 256;
    config.cache.sizeBytes = 8192;
    MicroScene scene;
    loadScene(scene, "builtin:showcase", config.bvh);
    const std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 64, 48);

    std::map<std::string, std::uint64_t> cycles;
    std::vector<SimRayResult> reference;
    for (const std::string policy : {"fifo", "oldestFirst", "treelet"}) {
        config.scheduler.policy = policy;
        RtCore core(config, *scene.model);
        const std::vector<SimRayResult> results = runBatch(core, rays);
        cycles[policy] = core.cycle();
        const auto stats = core.statsJson();
        EXPECT_EQ(stats["scheduler"]["policy"], policy);
        std::cout << "[ rtcore   ] policy " << policy << ": " << core.cycle() << " cycles, cache hit rate "
                  << stats["cache"]["hitRate"] << ", mean ray latency " << stats["rays"]["latency"]["mean"] << "\n";
        if (reference.empty()) {
            reference = results;
            continue;
        }
        for (std::size_t i = 0; i < rays.size(); ++i) {
            ASSERT_TRUE(sameHit(results[i].hit, reference[i].hit)) << policy << " ray " << i;
            ASSERT_TRUE(sameWork(results[i].work, reference[i].work)) << policy << " ray " << i;
        }
    }
    // Same work, different schedules: not all three take the same time.
    EXPECT_FALSE(cycles["fifo"] == cycles["oldestFirst"] && cycles["fifo"] == cycles["treelet"]);
    EXPECT_NE(cycles["fifo"], cycles["treelet"]);
}

TEST(RtCoreEquivalence, UnknownPolicyIsAnInputError) {
    RtCoreConfig config;
    EXPECT_THROW(config.set("scheduler.policy=random"), InputError);
    config.set("scheduler.policy=treelet");
    EXPECT_EQ(config.scheduler.policy, "treelet");
    const auto names = schedulerPolicyNames();
    // The built-ins first; a policy another test registered in the same
    // process (the registry is process-wide) may follow them.
    ASSERT_GE(names.size(), 3u);
    EXPECT_EQ(std::vector<std::string>(names.begin(), names.begin() + 3),
              (std::vector<std::string>{"fifo", "oldestFirst", "treelet"}));
    EXPECT_EQ(RtCoreConfig::describe()["scheduler"]["policy"]["allowed"], nlohmann::json(names));
}
