// The GPU level of the timing model (docs/rtcore-model.md, "GPU level"):
// one core with the ideal L2 is the single-core model bit for bit; two cores
// sharing L2 lines by hand; the laws the model obeys (Little's law on every
// queue, utilizations, DRAM peak, work bounds, determinism) on several
// workloads and configurations; the configuration's GPU sections.
#include "rtcore_golden.hpp"
#include "rtcore_gpu_golden.hpp"
#include "rtcore_timing_helpers.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/rtcore_sim/cache.hpp>

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using namespace rtlab::rtcore_sim::test_support;
using nlohmann::json;

namespace {

const ModelRay kDownOntoTriangle = makeModelRay(vec3(0.25f, 0.25f, 1.f), vec3(0.f, 0.f, -1.f));

std::string inputErrorOf(const std::function<void()>& fn) {
    try {
        fn();
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

// Primary rays of `source` (two ray types) in batches; returns the stats.
json runScene(const std::string& source, const RtCoreConfig& config, int width, int height,
              std::vector<SimRayResult>* resultsOut = nullptr, std::size_t batch = 2048) {
    MicroScene scene;
    loadScene(scene, source, config.bvh);
    std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, width, height);
    for (std::size_t i = 0; i < rays.size(); ++i) rays[i].rayType = static_cast<std::uint32_t>(i % 2);
    RtCore core(config, *scene.model);
    std::vector<SimRayResult> results(rays.size());
    OpaqueSide side;
    for (std::size_t first = 0; first < rays.size(); first += batch) {
        const std::size_t n = std::min(batch, rays.size() - first);
        core.run(std::span(rays).subspan(first, n), side, std::span(results).subspan(first, n));
    }
    if (resultsOut) {
        // Hits equal the functional traversal's, whatever the core.
        for (std::size_t i = 0; i < rays.size(); ++i) {
            TraversalCounters work;
            EXPECT_TRUE(sameHit(results[i].hit, traceClosestHit(*scene.model, rays[i].ray, work)))
                << source << " " << i;
            EXPECT_TRUE(sameWork(results[i].work, work)) << source << " " << i;
        }
        *resultsOut = results;
    }
    return core.statsJson();
}

std::uint64_t u64(const json& j) { return j.get<std::uint64_t>(); }

// Little's law on one queue: time-average occupancy = arrival rate x mean residence,
// i.e. (mean level x weight) = arrivals x mean residence.
void expectLittle(const json& occupancy, double arrivals, double residenceSum, const std::string& what) {
    const double levelCycles = occupancy["mean"].get<double>() * occupancy["count"].get<double>();
    const double meanResidence = arrivals > 0 ? residenceSum / arrivals : 0.0;
    const double rhs = arrivals * meanResidence;
    EXPECT_NEAR(levelCycles, rhs, 0.01 * std::max(rhs, 1.0)) << what;
}

// The laws of docs/rtcore-model.md ("Statistics") for one tree (the GPU's or one core's).
void expectCoreLaws(const json& s, const RtCoreConfig& config, std::uint32_t cores, const std::string& what) {
    const double cycles = s["frame"]["cycles"].get<double>();
    ASSERT_GT(cycles, 0.0) << what;
    const json& b = s["rays"]["latencyBreakdown"];
    const double latencySum = s["rays"]["latency"]["mean"].get<double>() * s["rays"]["latency"]["count"].get<double>();
    double parts = 0;
    for (const auto& [name, value] : b.items()) parts += value.get<double>();
    EXPECT_EQ(parts, latencySum) << what;
    const double rays = s["rays"]["completed"].get<double>();
    EXPECT_EQ(s["rays"]["submitted"], s["rays"]["completed"]) << what;
    // Little's law on every queue of the core.
    expectLittle(s["submission"]["inputQueue"]["occupancy"], rays, b["inputQueue"].get<double>(), what + " inputQueue");
    expectLittle(s["raySlots"]["occupancy"], rays,
                 latencySum - b["inputQueue"].get<double>() - b["completionQueue"].get<double>(), what + " raySlots");
    expectLittle(s["scheduler"]["readyRays"], s["scheduler"]["issued"].get<double>(), b["scheduler"].get<double>(),
                 what + " readyRays");
    expectLittle(s["completion"]["occupancy"], rays, b["completionQueue"].get<double>(), what + " completion");
    // Occupancy histograms cover every core-cycle.
    EXPECT_EQ(s["raySlots"]["occupancy"]["count"].get<double>(), cycles * cores) << what;
    // Utilizations in [0, 1]; work bounds of every unit pool, the scheduler and the ports.
    for (const char* unit : {"traversalUnits", "triangleUnits", "transformUnits"}) {
        const double u = s[unit]["utilization"].get<double>();
        EXPECT_GE(u, 0.0) << what << unit;
        EXPECT_LE(u, 1.0) << what << unit;
        EXPECT_GE(cycles, s[unit]["busyCycles"].get<double>() / s[unit]["units"].get<double>()) << what << unit;
    }
    for (const char* unit : {"scheduler", "memory"}) {
        EXPECT_GE(s[unit]["utilization"].get<double>(), 0.0) << what << unit;
        EXPECT_LE(s[unit]["utilization"].get<double>(), 1.0) << what << unit;
    }
    EXPECT_LE(s["raySlots"]["utilization"].get<double>(), 1.0) << what;
    EXPECT_GE(cycles * cores, s["memory"]["busyCycles"].get<double>()) << what;
    EXPECT_GE(cycles * cores, s["scheduler"]["issued"].get<double>() / config.scheduler.issueWidth) << what;
    EXPECT_GE(cycles * cores,
              s["traversalUnits"]["boxTests"].get<double>() / (config.traversal.units * config.traversal.boxesPerCycle))
        << what;
}

void expectGpuLaws(const json& s, const RtCoreConfig& config, const std::string& what) {
    const std::uint32_t n = config.gpu.cores;
    ASSERT_EQ(s["gpu"]["cores"], n) << what;
    ASSERT_EQ(s["cores"].size(), n) << what;
    expectCoreLaws(s, config, n, what + " gpu");
    std::uint64_t rays = 0, hits = 0, readBytes = 0;
    for (std::uint32_t k = 0; k < n; ++k) {
        const json& c = s["cores"][k];
        expectCoreLaws(c, config, 1, what + " core " + std::to_string(k));
        rays += u64(c["rays"]["completed"]);
        hits += u64(c["cache"]["hits"]);
        readBytes += u64(c["memory"]["readBytes"]);
    }
    // The aggregate is the sum of the cores.
    EXPECT_EQ(rays, u64(s["rays"]["completed"])) << what;
    EXPECT_EQ(hits, u64(s["cache"]["hits"])) << what;
    EXPECT_EQ(readBytes, u64(s["memory"]["readBytes"])) << what;
    // Shared L2 and DRAM.
    const double cycles = s["frame"]["cycles"].get<double>();
    const json& l2 = s["l2"];
    const json& dram = s["dram"];
    EXPECT_EQ(u64(l2["accesses"]), u64(l2["hits"]) + u64(l2["misses"])) << what;
    EXPECT_LE(l2["hitRate"].get<double>(), 1.0) << what;
    EXPECT_LE(dram["bytesPerCycle"].get<double>(), dram["peakBytesPerCycle"].get<double>()) << what;
    EXPECT_GE(dram["utilization"].get<double>(), 0.0) << what;
    EXPECT_LE(dram["utilization"].get<double>(), 1.0) << what;
    if (config.l2.mode == L2Mode::Cache) {
        // Every L1 miss and every prefetched line goes to the L2.
        const std::uint64_t prefetched = s["cache"].contains("prefetch") ? u64(s["cache"]["prefetch"]["lines"]) : 0;
        EXPECT_EQ(u64(l2["accesses"]), u64(s["cache"]["misses"]) + prefetched) << what;
        EXPECT_EQ(u64(dram["readBytes"]), u64(l2["misses"]) * config.l2.lineBytes) << what;
        EXPECT_LE(l2["bankUtilization"].get<double>(), 1.0) << what;
        EXPECT_LE(l2["busiestBankUtilization"].get<double>(), 1.0) << what;
        EXPECT_GE(cycles, l2["busiestBankBusyCycles"].get<double>()) << what;
        EXPECT_GE(cycles, dram["busiestChannelBusyCycles"].get<double>()) << what;
        EXPECT_GE(cycles, dram["readBytes"].get<double>() / dram["peakBytesPerCycle"].get<double>()) << what;
    } else {
        EXPECT_EQ(u64(l2["misses"]), 0u) << what;
        EXPECT_EQ(u64(dram["readBytes"]), 0u) << what;
    }
}

RtCoreConfig gpuConfig(std::uint32_t cores, L2Mode mode) {
    RtCoreConfig c;
    c.gpu.cores = cores;
    c.l2.mode = mode;
    return c;
}

// OpaqueSide's verdicts without allowing concurrent callbacks: the GPU runs
// the serial model (one host thread, cycle by cycle).
struct SerialOpaqueSide final : ProgrammableSide {
    CandidateVerdict triangle(std::uint32_t, const TriangleCandidate&) override { return {}; }
    ProceduralVerdict procedural(std::uint32_t, const ProceduralCandidate&) override { return {}; }
};

// Runs fn with `threads` host threads: a TBB limit and an arena of that size
// (3 threads oversubscribe this 2-core machine: the epochs' core groups differ all the same).
template <class Fn>
void withHostThreads(int threads, Fn&& fn) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    tbb::task_arena arena(threads);
    arena.execute(fn);
}

}  // namespace

TEST(RtCoreGpu, OneCoreWithIdealL2ReproducesTheSingleCoreModel) {
    // {workload, clock after the run, per-ray digest, stats digest}, computed by
    // rtcore_golden.hpp linked against the single-core model at commit 13d931e.
    struct Golden {
        int which;
        std::uint64_t cycles, rays, stats;
    };
    const Golden golden[] = {
#include "rtcore_golden_values.inc"
    };
    for (const Golden& g : golden) {
        RtCoreConfig config = goldenConfig(g.which);
        config.set("gpu.cores=1");
        config.set("l2.mode=ideal");
        const GoldenRun run = goldenRun(g.which, config);
        EXPECT_EQ(run.cycles, g.cycles) << "workload " << g.which;
        EXPECT_EQ(run.rayDigest, g.rays) << "workload " << g.which;
        EXPECT_EQ(run.statsDigest, g.stats) << "workload " << g.which;
    }
}

TEST(RtCoreGpu, TwoCoresShareOneL2LineByHand) {
    RtCoreConfig config;
    config.gpu.cores = 2;
    config.core.warpWidth = 1;
    config.l2.mode = L2Mode::Cache;
    config.memory.latency = 20;
    config.l2.hitLatency = 30;
    config.l2.bankCycles = 2;
    config.dram.latency = 100;
    config.dram.bytesPerCycle = 16;
    const std::uint64_t T = config.cache.lineBytes / config.memory.bytesPerCycle;  // 2
    const std::uint64_t Td = config.l2.lineBytes / config.dram.bytesPerCycle;      // 8
    const std::uint64_t unitTail = config.transform.latency + config.triangle.latency;
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);

    // Part 1: both cores miss the same three lines in the same cycles. Core 0
    // misses the L2; core 1 finds bank 0 busy for bankCycles, then a pending
    // hit on core 0's line: both rays wait T + hitLatency + Td + dram.latency
    // + memory.latency per step.
    {
        RtCore gpu(config, *scene.model);
        const auto r = runBatch(gpu, {simRay(kDownOntoTriangle), simRay(kDownOntoTriangle)});
        const std::uint64_t step = T + config.l2.hitLatency + Td + config.dram.latency + config.memory.latency;
        EXPECT_EQ(step, 160u);
        EXPECT_EQ(r[0].cycles, 3 * step + unitTail);
        EXPECT_EQ(r[1].cycles, 3 * step + unitTail);
        EXPECT_EQ(gpu.cycle(), 3 * step + unitTail);
        ASSERT_TRUE(r[0].hit.hit && r[1].hit.hit);
        const json s = gpu.statsJson();
        EXPECT_EQ(s["cores"][0]["rays"]["completed"], 1);
        EXPECT_EQ(s["cores"][1]["rays"]["completed"], 1);
        EXPECT_EQ(s["l2"]["accesses"], 6);
        EXPECT_EQ(s["l2"]["misses"], 3);
        EXPECT_EQ(s["l2"]["hits"], 3);
        EXPECT_EQ(s["l2"]["pendingHits"], 3);
        EXPECT_EQ(s["l2"]["bankConflicts"], 3);
        EXPECT_EQ(s["l2"]["bankWaitCycles"], 3 * config.l2.bankCycles);
        EXPECT_EQ(s["l2"]["busiestBankBusyCycles"], 6 * config.l2.bankCycles);  // lines 0, 32, 64: all bank 0
        EXPECT_EQ(s["dram"]["reads"], 3);
        EXPECT_EQ(s["dram"]["readBytes"], 3 * config.l2.lineBytes);
        EXPECT_EQ(s["dram"]["busyCycles"], 3 * Td);
        // Latency breakdown: core 0's fetches spend hitLatency in the L2 and
        // Td + dram.latency in DRAM; core 1's wait bankCycles longer in the L2
        // and as much less for the pending fill.
        const json& b = s["rays"]["latencyBreakdown"];
        EXPECT_EQ(b["l2"], 3 * (config.l2.hitLatency + config.l2.hitLatency + config.l2.bankCycles));
        EXPECT_EQ(b["dram"], 3 * ((Td + config.dram.latency) + (Td + config.dram.latency - config.l2.bankCycles)));
        EXPECT_EQ(b["fetch"], 6 * (T + config.memory.latency));
    }
    // Part 2: one ray alone on core 0 fills the L2; then the pair again: core 0
    // hits its L1, core 1 misses its L1 and hits the L2 lines core 0 brought in.
    {
        RtCore gpu(config, *scene.model);
        const auto alone = runBatch(gpu, {simRay(kDownOntoTriangle)});
        const std::uint64_t coldStep = T + config.l2.hitLatency + Td + config.dram.latency + config.memory.latency;
        EXPECT_EQ(alone[0].cycles, 3 * coldStep + unitTail);
        const std::uint64_t start = gpu.cycle();
        gpu.resetStats();
        const auto r = runBatch(gpu, {simRay(kDownOntoTriangle), simRay(kDownOntoTriangle)});
        EXPECT_EQ(r[0].cycles, 3 * config.cache.hitLatency + unitTail);                             // 24
        EXPECT_EQ(r[1].cycles, 3 * (T + config.l2.hitLatency + config.memory.latency) + unitTail);  // 168
        EXPECT_EQ(gpu.cycle(), start + r[1].cycles);
        const json s = gpu.statsJson();
        EXPECT_EQ(s["l2"]["accesses"], 3);
        EXPECT_EQ(s["l2"]["hits"], 3);
        EXPECT_EQ(s["l2"]["pendingHits"], 0);
        EXPECT_EQ(s["l2"]["bankConflicts"], 0);
        EXPECT_EQ(s["dram"]["reads"], 0);
        EXPECT_EQ(s["cores"][0]["cache"]["hits"], 3);
        EXPECT_EQ(s["cores"][1]["cache"]["misses"], 3);
        EXPECT_EQ(s["rays"]["latencyBreakdown"]["l2"], 3 * config.l2.hitLatency);
        EXPECT_EQ(s["rays"]["latencyBreakdown"]["dram"], 0);
    }
}

TEST(RtCoreGpu, L2ServiceOrderByHand) {
    // One bank (4 cycles an access, hit latency 10), one DRAM channel (a
    // 128-byte line at 16 bytes per cycle: 8 cycles, latency 100); four
    // misses to different lines, given in the order made:
    //   A made 0, arriving 100;  B made 1, arriving 10;  C made 2, arriving 98;
    //   D made 200, arriving 200.
    L2Params l2{.mode = L2Mode::Cache,
                .sizeBytes = 4096,
                .lineBytes = 128,
                .ways = 4,
                .banks = 1,
                .bankCycles = 4,
                .hitLatency = 10};
    const DramParams dram{.channels = 1, .bytesPerCycle = 16, .latency = 100};
    struct Waits {
        std::uint64_t conflicts, waitCycles;
    };
    const auto run = [&](ServiceOrder order) {
        l2.serviceOrder = order;
        SharedL2 cache(l2, dram);
        std::vector<std::uint64_t> ready;
        ready.push_back(cache.access(0 * 128, 0, 100).ready);
        ready.push_back(cache.access(1 * 128, 1, 10).ready);
        ready.push_back(cache.access(2 * 128, 2, 98).ready);
        ready.push_back(cache.access(3 * 128, 200, 200).ready);
        EXPECT_EQ(cache.counters.misses, 4u);
        EXPECT_EQ(cache.bankBusyCycles(0), 4u * 4u);
        EXPECT_EQ(cache.channelBusyCycles(0), 4u * 8u);
        return std::make_pair(ready, Waits{cache.counters.bankConflicts, cache.counters.bankWaitCycles});
    };
    // Order made: A holds the bank 100-104 and the channel 110-118 (filled
    // 218); B waits for the bank until 104 (tag 114), the channel until 118
    // (226); C until 108 (tag 118), the channel until 126 (234); D finds
    // both free (tag 210, filled 318).
    const auto [made, madeCounts] = run(ServiceOrder::Made);
    EXPECT_EQ(made, (std::vector<std::uint64_t>{218, 226, 234, 318}));
    EXPECT_EQ(madeCounts.conflicts, 2u);
    EXPECT_EQ(madeCounts.waitCycles, (104u - 10u) + (108u - 98u));
    // Order of arrival: B takes the idle bank at 10 (tag 20) and the idle
    // channel at 20 (filled 128); C's 4 cycles from 98 would overlap A's
    // 100-104, so it starts at 104 (tag 114) and its channel slot after A's
    // 110-118 (226); D alike (the reservations before 200 are dropped).
    const auto [arrival, arrivalCounts] = run(ServiceOrder::Arrival);
    EXPECT_EQ(arrival, (std::vector<std::uint64_t>{218, 128, 226, 318}));
    EXPECT_EQ(arrivalCounts.conflicts, 1u);
    EXPECT_EQ(arrivalCounts.waitCycles, 104u - 98u);
}

TEST(RtCoreGpu, DispatchRulesAssignWarpsToCores) {
    // 11 rays in warps of 2: 6 warps (the last one short) on 4 cores.
    // roundRobin: core w mod 4 -> warps {0,4} {1,5} {2} {3} -> rays 4, 3, 2, 2;
    // contiguous: core floor(w * 4 / 6) -> warps {0,1} {2} {3,4} {5} -> rays 4, 2, 4, 1.
    MicroScene scene;
    makeOneTriangleScene(scene, BvhParams{});
    const std::vector<SimRay> rays(11, simRay(kDownOntoTriangle));
    const std::pair<WarpDispatch, std::vector<std::uint64_t>> cases[] = {
        {WarpDispatch::RoundRobin, {4, 3, 2, 2}},
        {WarpDispatch::Contiguous, {4, 2, 4, 1}},
    };
    for (const auto& [rule, expected] : cases) {
        RtCoreConfig config;
        config.gpu.cores = 4;
        config.gpu.dispatch = rule;
        config.core.warpWidth = 2;
        RtCore gpu(config, *scene.model);
        const auto results = runBatch(gpu, rays);
        const json s = gpu.statsJson();
        EXPECT_EQ(s["gpu"]["dispatch"], toString(rule));
        for (std::uint32_t k = 0; k < 4; ++k)
            EXPECT_EQ(u64(s["cores"][k]["rays"]["completed"]), expected[k]) << toString(rule) << " core " << k;
        for (const SimRayResult& r : results) EXPECT_TRUE(r.hit.hit);
    }
}

TEST(RtCoreGpu, LawsHoldOnSeveralWorkloadsAndConfigurations) {
    RtCoreConfig scarce = gpuConfig(8, L2Mode::Cache);
    scarce.core.warpWidth = 8;
    scarce.core.inputQueueRays = 16;
    scarce.core.raySlots = 16;
    scarce.core.completionQueueRays = 2;
    scarce.core.completionPerCycle = 1;
    scarce.cache.sizeBytes = 2048;
    scarce.cache.ways = 2;
    scarce.stack.shortStackEntries = 2;
    scarce.stack.refillEntries = 1;
    scarce.l2.sizeBytes = 16384;
    scarce.l2.ways = 2;
    scarce.l2.banks = 4;
    scarce.l2.bankCycles = 4;
    scarce.dram.channels = 1;
    scarce.dram.bytesPerCycle = 4;
    scarce.scheduler.policy = "treelet";
    RtCoreConfig reordered = gpuConfig(8, L2Mode::Cache);
    reordered.gpu.rayOrder = RayOrder::DirectionOrigin;
    RtCoreConfig contiguous = gpuConfig(2, L2Mode::Cache);
    contiguous.gpu.dispatch = WarpDispatch::Contiguous;
    const std::pair<std::string, RtCoreConfig> configs[] = {
        {"1 core ideal", gpuConfig(1, L2Mode::Ideal)},
        {"1 core cache", gpuConfig(1, L2Mode::Cache)},
        {"2 cores cache contiguous", contiguous},
        {"8 cores ideal", gpuConfig(8, L2Mode::Ideal)},
        {"8 cores cache", gpuConfig(8, L2Mode::Cache)},
        {"8 cores scarce", scarce},
        {"8 cores cache directionOrigin", reordered},
        {"8 cores scarce, served in arrival order",
         [&] {
             RtCoreConfig c = scarce;
             c.l2.serviceOrder = ServiceOrder::Arrival;
             return c;
         }()},
        {"8 cores cache treeletPrefetch",
         [] {
             RtCoreConfig c = gpuConfig(8, L2Mode::Cache);
             c.scheduler.policy = "treeletPrefetch";
             return c;
         }()},
    };
    for (const char* source : {"builtin:showcase", "builtin:terrain?triangles=20000"}) {
        for (const auto& [name, config] : configs) {
            std::vector<SimRayResult> results;
            const json s = runScene(source, config, 64, 48, &results);
            expectGpuLaws(s, config, std::string(source) + " " + name);
            if (name == "8 cores cache treeletPrefetch") {
                ASSERT_TRUE(s["cache"].contains("prefetch")) << source;
                EXPECT_GT(u64(s["cache"]["prefetch"]["lines"]), 0u) << source;
                EXPECT_GT(u64(s["cache"]["prefetch"]["usefulLines"]), 0u) << source;
                EXPECT_LE(u64(s["cache"]["prefetch"]["usefulLines"]), u64(s["cache"]["prefetch"]["lines"])) << source;
            } else {
                EXPECT_FALSE(s["cache"].contains("prefetch")) << source << " " << name;
            }
            if (name.starts_with("8 cores scarce")) {
                EXPECT_GT(u64(s["l2"]["bankConflicts"]), 0u) << source;
                EXPECT_GT(u64(s["dram"]["queueCycles"]), 0u) << source;
                EXPECT_GT(u64(s["l2"]["evictions"]), 0u) << source;
            }
        }
    }
}

TEST(RtCoreGpu, MoreCoresFinishSoonerAndASmallerL2MissesMore) {
    // Not a calibration, a sanity check of the direction of effects on a
    // memory-heavy workload: 8 cores take fewer cycles than 1; a 16 KiB L2
    // misses more (and moves more DRAM bytes) than a 4 MiB one.
    const std::string source = "builtin:terrain?triangles=20000";
    const json one = runScene(source, gpuConfig(1, L2Mode::Cache), 64, 48);
    const json eight = runScene(source, gpuConfig(8, L2Mode::Cache), 64, 48);
    EXPECT_LT(u64(eight["frame"]["cycles"]), u64(one["frame"]["cycles"]));
    RtCoreConfig small = gpuConfig(8, L2Mode::Cache);
    small.l2.sizeBytes = 16384;
    small.l2.ways = 4;
    small.l2.banks = 4;
    const json smallL2 = runScene(source, small, 64, 48);
    EXPECT_LT(smallL2["l2"]["hitRate"].get<double>(), eight["l2"]["hitRate"].get<double>());
    EXPECT_GT(u64(smallL2["dram"]["readBytes"]), u64(eight["dram"]["readBytes"]));
}

TEST(RtCoreGpu, IdenticalAcrossRunsAndHostThreadCounts) {
    // 8 cores with the L2 in mode cache on two workloads: the cores run in
    // host-parallel epochs (OpaqueSide allows concurrent callbacks) on 1, 2,
    // 3 and 4 host threads; everything equals the default run's.
    for (const char* source : {"builtin:showcase", "builtin:terrain?triangles=20000"}) {
        RtCoreConfig config = gpuConfig(8, L2Mode::Cache);
        config.scheduler.policy = "treelet";
        std::vector<SimRayResult> a, b, c;
        const json first = runScene(source, config, 64, 48, &a);
        json inArena;
        tbb::task_arena arena(4);
        arena.execute([&] { inArena = runScene(source, config, 64, 48, &b); });
        json limited;
        {
            tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
            limited = runScene(source, config, 64, 48, &c);
        }
        EXPECT_EQ(first, inArena) << source;
        EXPECT_EQ(first, limited) << source;
        ASSERT_EQ(a.size(), b.size());
        for (std::size_t i = 0; i < a.size(); ++i) {
            ASSERT_EQ(a[i].cycles, b[i].cycles) << source << " " << i;
            ASSERT_EQ(a[i].cycles, c[i].cycles) << source << " " << i;
            ASSERT_EQ(a[i].slotCycles, c[i].slotCycles) << source << " " << i;
        }
        for (int threads : {2, 3}) {
            std::vector<SimRayResult> d;
            json withThreads;
            withHostThreads(threads, [&] { withThreads = runScene(source, config, 64, 48, &d); });
            EXPECT_EQ(first, withThreads) << source << " " << threads << " threads";
            for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i].cycles, d[i].cycles) << source << " " << i;
        }
    }
}

TEST(RtCoreGpu, HostParallelEpochsReproduceTheSerialGpuModel) {
    // {workload, clock after the run, per-ray digest, stats digest}, computed by
    // rtcore_gpu_golden.hpp against the GPU model before host-parallel epochs
    // (commit e3caa2e: one host thread, cores cycle by cycle).
    struct Golden {
        int which;
        std::uint64_t cycles, rays, stats;
    };
    const Golden golden[] = {
#include "rtcore_gpu_golden_values.inc"
    };
    ASSERT_EQ(std::size(golden), std::size_t(kGpuGoldenWorkloads));
    for (const Golden& g : golden) {
        const RtCoreConfig config = gpuGoldenConfig(g.which);
        GpuGoldenScene scene;
        loadGpuGoldenScene(scene, g.which, config);
        const auto expectGolden = [&](const GoldenRun& run, const std::string& how) {
            EXPECT_EQ(run.cycles, g.cycles) << "workload " << g.which << ", " << how;
            EXPECT_EQ(run.rayDigest, g.rays) << "workload " << g.which << ", " << how;
            EXPECT_EQ(run.statsDigest, g.stats) << "workload " << g.which << ", " << how;
        };
        {
            // The serial model (a side that does not allow concurrent callbacks).
            RtCore gpu(config, *scene.scene.model);
            SerialOpaqueSide side;
            expectGolden(gpuGoldenRun(gpu, scene.rays, side), "serial");
        }
        // Host-parallel epochs on 1, 2 and 3 host threads.
        for (int threads : {1, 2, 3}) {
            withHostThreads(threads, [&] {
                RtCore gpu(config, *scene.scene.model);
                OpaqueSide side;
                expectGolden(gpuGoldenRun(gpu, scene.rays, side), std::to_string(threads) + " host threads");
            });
        }
        if (g.which == 4) {  // visiting every cycle in the epochs changes nothing either
            withHostThreads(2, [&] {
                RtCore gpu(config, *scene.scene.model);
                gpu.simulateEveryCycle(true);
                OpaqueSide side;
                expectGolden(gpuGoldenRun(gpu, scene.rays, side), "every cycle, 2 host threads");
            });
        }
    }
}

TEST(RtCoreGpu, ArrivalServiceOrderIsTheSameSeriallyAndOnHostThreads) {
    // l2.serviceOrder=arrival on the golden workloads with a modelled L2: the
    // serial model and host-parallel epochs on 1, 2 and 3 host threads give
    // the same clock, per-ray figures and statistics; and the order matters
    // (some workload's cycles differ from the order made).
    bool someDiffer = false;
    for (int which = 0; which < kGpuGoldenWorkloads; ++which) {
        RtCoreConfig config = gpuGoldenConfig(which);
        if (config.l2.mode != L2Mode::Cache) continue;
        GpuGoldenScene scene;
        loadGpuGoldenScene(scene, which, config);
        RtCore madeGpu(config, *scene.scene.model);
        OpaqueSide madeSide;
        const GoldenRun made = gpuGoldenRun(madeGpu, scene.rays, madeSide);
        config.l2.serviceOrder = ServiceOrder::Arrival;
        RtCore serialGpu(config, *scene.scene.model);
        SerialOpaqueSide serialSide;
        const GoldenRun serial = gpuGoldenRun(serialGpu, scene.rays, serialSide);
        expectGpuLaws(serialGpu.statsJson(), config, "workload " + std::to_string(which) + " arrival");
        someDiffer = someDiffer || serial.cycles != made.cycles;
        for (int threads : {1, 2, 3}) {
            withHostThreads(threads, [&] {
                RtCore gpu(config, *scene.scene.model);
                OpaqueSide side;
                const GoldenRun run = gpuGoldenRun(gpu, scene.rays, side);
                EXPECT_EQ(run.cycles, serial.cycles) << which << ", " << threads << " host threads";
                EXPECT_EQ(run.rayDigest, serial.rayDigest) << which << ", " << threads << " host threads";
                EXPECT_EQ(run.statsDigest, serial.statsDigest) << which << ", " << threads << " host threads";
            });
        }
    }
    EXPECT_TRUE(someDiffer);
}

TEST(RtCoreGpu, ASideThatThrowsInHostParallelEpochsGivesTheSameStateOnAnyThreadCount) {
    // A concurrent side whose callback for one ray throws: the batch is
    // dropped and the exception propagates; the clock reached and the
    // statistics are the same for 1, 2 and 3 host threads, and the GPU
    // stays usable.
    struct ThrowingSide final : ProgrammableSide {
        std::uint32_t throwFor = ~0u;
        CandidateVerdict triangle(std::uint32_t ray, const TriangleCandidate&) override {
            if (ray == throwFor) throw std::runtime_error("shader failed");
            return {};
        }
        ProceduralVerdict procedural(std::uint32_t, const ProceduralCandidate&) override { return {}; }
        bool concurrent() const override { return true; }
    };
    RtCoreConfig config = gpuConfig(8, L2Mode::Cache);
    MicroScene scene;
    loadScene(scene, "builtin:showcase", config.bvh);
    const std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 64, 48);
    std::vector<std::uint64_t> reached;
    std::vector<json> stats;
    for (int threads : {1, 2, 3}) {
        withHostThreads(threads, [&] {
            RtCore gpu(config, *scene.model);
            ThrowingSide side;
            side.throwFor = 1500;
            std::vector<SimRayResult> results(rays.size());
            EXPECT_THROW(gpu.run(rays, side, results), std::runtime_error);
            reached.push_back(gpu.cycle());
            side.throwFor = ~0u;
            gpu.run(rays, side, results);
            for (std::size_t i = 0; i < rays.size(); ++i) {
                TraversalCounters work;
                ASSERT_TRUE(sameHit(results[i].hit, traceClosestHit(*scene.model, rays[i].ray, work))) << i;
            }
            stats.push_back(gpu.statsJson());
        });
    }
    ASSERT_EQ(reached.size(), 3u);
    EXPECT_GT(reached[0], 0u);
    EXPECT_EQ(reached[0], reached[1]);
    EXPECT_EQ(reached[0], reached[2]);
    EXPECT_EQ(stats[0], stats[1]);
    EXPECT_EQ(stats[0], stats[2]);
    // The rays returned before the exception, then the whole second batch.
    EXPECT_GE(stats[0]["rays"]["completed"].get<std::size_t>(), rays.size());
}

TEST(RtCoreGpu, SkippingIdleCyclesChangesNothingOnSeveralCores) {
    MicroScene scene;
    RtCoreConfig config = gpuConfig(4, L2Mode::Cache);
    config.core.warpWidth = 8;
    config.l2.sizeBytes = 16384;
    config.l2.ways = 2;
    config.l2.banks = 4;
    loadScene(scene, "builtin:showcase", config.bvh);
    const std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 32, 24);
    json stats[2];
    std::vector<SimRayResult> results[2];
    for (int every = 0; every < 2; ++every) {
        RtCore gpu(config, *scene.model);
        gpu.simulateEveryCycle(every == 1);
        results[every] = runBatch(gpu, rays);
        stats[every] = gpu.statsJson();
    }
    EXPECT_EQ(stats[0], stats[1]);
    for (std::size_t i = 0; i < rays.size(); ++i) ASSERT_EQ(results[0][i].cycles, results[1][i].cycles) << i;
}

TEST(RtCoreGpu, ConfigurationSectionsAndErrors) {
    const RtCoreConfig defaults;
    EXPECT_EQ(defaults.gpu.cores, 1u);
    EXPECT_EQ(defaults.l2.mode, L2Mode::Ideal);
    const json described = RtCoreConfig::describe();
    for (const char* key :
         {"gpu.cores", "gpu.dispatch", "l2.mode", "l2.sizeBytes", "l2.lineBytes", "l2.ways", "l2.banks",
          "l2.bankCycles", "l2.hitLatency", "dram.channels", "dram.bytesPerCycle", "dram.latency"}) {
        const std::string k(key);
        const std::string section = k.substr(0, k.find('.')), field = k.substr(k.find('.') + 1);
        ASSERT_TRUE(described[section].contains(field)) << key;
        EXPECT_FALSE(described[section][field]["description"].get<std::string>().empty()) << key;
        EXPECT_EQ(described[section][field]["default"], defaults.toJson()[section][field]) << key;
    }
    RtCoreConfig c;
    c.set("gpu.cores=8");
    c.set("gpu.dispatch=contiguous");
    c.set("l2.mode=cache");
    c.set("l2.sizeBytes=1048576");
    c.set("dram.channels=8");
    EXPECT_NO_THROW(c.validate("cfg"));
    EXPECT_EQ(c.gpu.cores, 8u);
    EXPECT_EQ(c.gpu.dispatch, WarpDispatch::Contiguous);
    EXPECT_EQ(RtCoreConfig::fromJson(c.toJson(), "echo").toJson(), c.toJson());

    EXPECT_NE(inputErrorOf([&] {
                  RtCoreConfig x;
                  x.set("gpu.cores=0");
              }).find("gpu.cores"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([&] {
                  RtCoreConfig x;
                  x.set("gpu.dispatch=byTile");
              }).find("gpu.dispatch"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([&] {
                  RtCoreConfig x;
                  x.set("l2.lineBytes=100");
              }).find("l2.lineBytes"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([&] {
                  RtCoreConfig x;
                  x.set("dram.channels=65");
              }).find("dram.channels"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([&] {
                  RtCoreConfig x;
                  x.set("l2.assoc=4");
              }).find("l2.assoc: unknown key"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([&] {
                  RtCoreConfig x;
                  x.l2.sizeBytes = 3 * 128 * 16 * 16;
                  x.validate("cfg");
              }).find("l2.sizeBytes"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([&] {
                  RtCoreConfig x;
                  x.l2.mode = L2Mode::Cache;
                  x.cache.lineBytes = 256;
                  x.validate("cfg");
              }).find("l2.lineBytes"),
              std::string::npos);
    EXPECT_NE(inputErrorOf([&] {
                  RtCoreConfig x;
                  x.l2.mode = L2Mode::Cache;
                  x.l2.bankCycles = 8;
                  x.l2.hitLatency = 4;
                  x.validate("cfg");
              }).find("l2.hitLatency"),
              std::string::npos);
    // The ideal L2 does not constrain the L1 line (configurations from before the GPU level stay valid).
    RtCoreConfig old;
    old.cache.lineBytes = 256;
    old.cache.sizeBytes = 32768;
    EXPECT_NO_THROW(old.validate("cfg"));
}

TEST(RtCoreGpu, RayReorderingChangesCyclesNotHitsAndSidesSeeTheCallersIndices) {
    // A side that rejects every candidate of odd ray indices: whatever the
    // order of warp formation, exactly the even rays of the caller's batch hit.
    struct EvenRaysOnly final : ProgrammableSide {
        CandidateVerdict triangle(std::uint32_t ray, const TriangleCandidate&) override {
            CandidateVerdict v;
            v.commit = ray % 2 == 0;
            return v;
        }
        ProceduralVerdict procedural(std::uint32_t, const ProceduralCandidate&) override { return {}; }
    };
    RtCoreConfig config = gpuConfig(4, L2Mode::Cache);
    MicroScene scene;
    loadScene(scene, "builtin:showcase", config.bvh);
    std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 48, 32);
    // Interleave two cameras' worth of directions so that the order matters: reverse every other row.
    for (std::size_t i = 0; i + 1 < rays.size(); i += 96) std::reverse(rays.begin() + i, rays.begin() + i + 48);
    std::vector<SimRayResult> plain(rays.size()), sorted(rays.size());
    {
        RtCore gpu(config, *scene.model);
        EvenRaysOnly side;
        gpu.run(rays, side, plain);
    }
    config.gpu.rayOrder = RayOrder::DirectionOrigin;
    RtCore gpu(config, *scene.model);
    EvenRaysOnly side;
    gpu.run(rays, side, sorted);
    EXPECT_EQ(gpu.statsJson()["gpu"]["rayOrder"], "directionOrigin");
    std::size_t hits = 0, differentLatency = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
        ASSERT_TRUE(sameHit(plain[i].hit, sorted[i].hit)) << i;
        ASSERT_TRUE(sameWork(plain[i].work, sorted[i].work)) << i;
        if (i % 2 == 1) {
            ASSERT_FALSE(sorted[i].hit.hit) << i;
        }
        hits += sorted[i].hit.hit;
        differentLatency += plain[i].cycles != sorted[i].cycles;
    }
    EXPECT_GT(hits, rays.size() / 4);
    EXPECT_GT(differentLatency, 0u);  // warps were formed differently
}

TEST(RtCoreGpu, TreeletPrefetchReadsAheadWithoutDelayingTheRay) {
    // The cold one-triangle ray (3 steps, each in its own 4096-byte treelet:
    // TLAS leaf at 0, instance at 4096, BLAS leaf at 8192). Each step's demand
    // miss goes first; then the prefetch of prefetchBytes = 256 from the same
    // address reads the three lines after it (64..255 past the step's
    // address) - 9 lines, none of them used by this ray - while the ray still
    // takes 3 (T + L) + transform + triangle cycles: the port is free again
    // long before the next demand miss.
    RtCoreConfig config;
    config.scheduler.policy = "treeletPrefetch";
    MicroScene scene;
    makeOneTriangleScene(scene, config.bvh);
    RtCore core(config, *scene.model);
    const auto r = runBatch(core, {simRay(kDownOntoTriangle)});
    const std::uint64_t T = config.cache.lineBytes / config.memory.bytesPerCycle;
    EXPECT_EQ(r[0].cycles, 3 * (T + config.memory.latency) + config.transform.latency + config.triangle.latency);
    const json s = core.statsJson();
    EXPECT_EQ(s["cache"]["prefetch"]["requests"], 3);
    EXPECT_EQ(s["cache"]["prefetch"]["lines"], 9);
    EXPECT_EQ(s["cache"]["prefetch"]["usefulLines"], 0);
    EXPECT_EQ(s["memory"]["reads"], 12);
    EXPECT_EQ(s["scheduler"]["treeletEntries"], 3);
    // The same ray again: every line is cached, no treelet prefetch reads anything.
    core.resetStats();
    runBatch(core, {simRay(kDownOntoTriangle)});
    EXPECT_EQ(core.statsJson()["cache"]["prefetch"]["lines"], 0);
    EXPECT_EQ(core.statsJson()["memory"]["reads"], 0);
}

TEST(RtCoreGpu, SectoredCachesGiveTheSameLaunchSeriallyAndOnHostThreads) {
    // h100-like's memory side (128-byte L1 lines of 32-byte sectors, 64-byte
    // L2 lines) on four cores, with and without treelet prefetching (whole
    // lines read one sector at a time): the serial model and host-parallel
    // epochs on 2 and 3 threads give the same cycles, per-ray results and stats.
    for (const char* policy : {"fifo", "treeletPrefetch"}) {
        RtCoreConfig config;
        config.gpu.cores = 4;
        config.gpu.residentWarps = 4;
        config.l2.mode = L2Mode::Cache;
        config.cache.lineBytes = 128;
        config.cache.sectorBytes = 32;
        config.cache.ways = 4;
        config.cache.sizeBytes = 128 * 4 * 8;
        config.l2.lineBytes = 64;
        config.l2.sizeBytes = 64 * 16 * 16 * 16;
        config.scheduler.policy = policy;
        SCOPED_TRACE(policy);
        MicroScene scene;
        loadScene(scene, "builtin:terrain?triangles=20000", config.bvh);
        const std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 48, 32);
        std::vector<std::uint32_t> threads(rays.size());
        for (std::uint32_t t = 0; t < threads.size(); ++t) threads[t] = t;
        const auto run = [&](ProgrammableSide& side, std::vector<SimRayResult>& results) {
            RtCore core(config, *scene.model);
            results.assign(rays.size(), SimRayResult{});
            core.runLaunch(rays, threads, static_cast<std::uint32_t>(rays.size()), side, results);
            nlohmann::json stats = core.statsJson();
            stats["clock"] = core.cycle();
            return stats;
        };
        SerialOpaqueSide serialSide;
        std::vector<SimRayResult> serial;
        const nlohmann::json expected = run(serialSide, serial);
        EXPECT_GT(expected["cache"]["misses"].get<std::uint64_t>(), 0u);
        EXPECT_EQ(expected["cache"]["sizeBytes"], config.cache.sizeBytes);
        for (const int hostThreads : {2, 3}) {
            std::vector<SimRayResult> parallel;
            nlohmann::json stats;
            withHostThreads(hostThreads, [&] {
                OpaqueSide side;
                stats = run(side, parallel);
            });
            EXPECT_EQ(stats, expected) << hostThreads << " host threads";
            for (std::size_t i = 0; i < rays.size(); ++i) ASSERT_EQ(parallel[i].cycles, serial[i].cycles) << i;
        }
    }
}
