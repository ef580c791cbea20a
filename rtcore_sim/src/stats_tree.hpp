#pragma once
// The counters behind RtCore's stats tree: one core's raw counters and snapshot, the per-ray-type sums
// (docs/rtcore-model.md, "Statistics"); stats_tree.cpp turns them into JSON. Internal to rtcore_sim.
#include <rtlab/rtcore_sim/stats.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>

namespace rtlab::rtcore_sim {

constexpr std::uint32_t kWorkHistogramBuckets = 256;
constexpr std::uint32_t kMaxRayTypes = 1024;

inline Histogram workHistogram() { return Histogram(Histogram::Scheme::Linear, kWorkHistogramBuckets); }

struct RayTypeStats {
    std::uint64_t rays = 0;
    Histogram latency{Histogram::Scheme::Log2};
    std::uint64_t nodeVisits = 0, triangleTests = 0, instanceTransitions = 0;
    std::uint64_t inFlight = 0, activeSince = 0, activeCycles = 0;
};

// One core's share of a ray type's sums during a batch (added to the GPU's
// RayTypeStats, in core order, when the batch ends).
struct RayTypeWork {
    std::uint64_t rays = 0;
    Histogram latency{Histogram::Scheme::Log2};
    std::uint64_t nodeVisits = 0, triangleTests = 0, instanceTransitions = 0;
};

// A change of a ray type's rays in flight on one core (+ submitted, - returned).
// A type's activity is a union over the cores, so these are replayed in the
// serial order (cycle, core, the core's order) when the batch ends.
struct Activity {
    std::uint64_t cycle;
    std::uint32_t type;
    std::int32_t delta;
};

// ---------------------------------------------------------------------------
// Raw counters of one core; the GPU's aggregate is their sum over the cores.

#define RTCORE_SIM_CORE_COUNTERS(X)                                                                                  \
    X(warps)                                                                                                         \
    X(raysSubmitted)                                                                                                 \
    X(raysCompleted) X(inputQueue) X(scheduler) X(fetch) X(l2) X(dram) X(boxUnitWait) X(boxUnit) X(triangleUnitWait) \
        X(triangleUnit) X(transformUnitWait) X(transformUnit) X(shader) X(stackRefill) X(completionBlocked)          \
            X(completionQueue) X(fetchBeyondHit) X(inputQueueFull) X(noFreeRaySlot) X(completionQueueFull) X(issued) \
                X(issueCycles) X(nodes) X(boxes) X(leaves) X(triangleTestCount) X(proceduralTestCount) X(transforms) \
                    X(fetches) X(fetchBytes) X(anyHitCalls) X(intersectionCalls) X(pushes) X(pops) X(spilledEntries) \
                        X(spillWrites) X(refills) X(refilledEntries) X(warpsCompleted) X(warpSteps) X(warpLanes)     \
                            X(raySteps)
#define RTCORE_SIM_CORE_HISTOGRAMS(X)                                                                  \
    X(latency)                                                                                         \
    X(steps)                                                                                           \
    X(nodeVisits) X(leafVisits) X(boxTests) X(triangleTests) X(proceduralTests) X(instanceTransitions) \
        X(maxStackDepth) X(activeRaysPerWarpStep)

struct CoreStats {
    // Ray latency breakdown (ray-cycles; the parts sum to the latencies): inputQueue, scheduler, fetch, l2, dram,
    // boxUnitWait ... completionQueue. fetchBeyondHit is part of fetch + l2 + dram (cycles beyond the hit latency).
#define X(name) std::uint64_t name = 0;
    RTCORE_SIM_CORE_COUNTERS(X)
#undef X
    Histogram latency{Histogram::Scheme::Log2};
    Histogram steps = workHistogram(), nodeVisits = workHistogram(), leafVisits = workHistogram(),
              boxTests = workHistogram(), triangleTests = workHistogram(), proceduralTests = workHistogram(),
              instanceTransitions = workHistogram(), maxStackDepth = workHistogram();
    Histogram activeRaysPerWarpStep{Histogram::Scheme::Linear, 65};

    void merge(const CoreStats& o) {
#define X(name) name += o.name;
        RTCORE_SIM_CORE_COUNTERS(X)
#undef X
#define X(name) name.merge(o.name);
        RTCORE_SIM_CORE_HISTOGRAMS(X)
#undef X
    }
};

struct UnitCounters {
    std::uint64_t requests = 0, busyCycles = 0, waitCycles = 0;
    void merge(const UnitCounters& o) {
        requests += o.requests;
        busyCycles += o.busyCycles;
        waitCycles += o.waitCycles;
    }
};

// What the stats tree of one core (or of all cores, merged) is dumped from.
struct CoreSnapshot {
    CoreStats stats;
    UnitCounters box, triangle, transform;
    std::uint64_t cacheAccesses = 0, cacheHits = 0, cachePendingHits = 0, cacheMisses = 0, cacheEvictions = 0,
                  cacheInvalidations = 0, prefetchRequests = 0, prefetchLines = 0, prefetchHits = 0;
    std::uint64_t memReads = 0, memReadBytes = 0, memWrites = 0, memWriteBytes = 0, memBusy = 0, memQueue = 0;
    Histogram inputQueueOcc, slotOcc, readyOcc, completionOcc;
    nlohmann::json policyStats = nlohmann::json::object();

    void merge(const CoreSnapshot& o) {
        stats.merge(o.stats);
        box.merge(o.box);
        triangle.merge(o.triangle);
        transform.merge(o.transform);
        cacheAccesses += o.cacheAccesses;
        cacheHits += o.cacheHits;
        cachePendingHits += o.cachePendingHits;
        cacheMisses += o.cacheMisses;
        cacheEvictions += o.cacheEvictions;
        cacheInvalidations += o.cacheInvalidations;
        prefetchRequests += o.prefetchRequests;
        prefetchLines += o.prefetchLines;
        prefetchHits += o.prefetchHits;
        memReads += o.memReads;
        memReadBytes += o.memReadBytes;
        memWrites += o.memWrites;
        memWriteBytes += o.memWriteBytes;
        memBusy += o.memBusy;
        memQueue += o.memQueue;
        inputQueueOcc.merge(o.inputQueueOcc);
        slotOcc.merge(o.slotOcc);
        readyOcc.merge(o.readyOcc);
        completionOcc.merge(o.completionOcc);
        // Policy counters add up; the configuration echo (treeletBytes) and non-numbers stay.
        for (const auto& [key, value] : o.policyStats.items()) {
            nlohmann::json& mine = policyStats[key];
            if (key != "treeletBytes" && value.is_number_integer() && mine.is_number_integer())
                mine = mine.get<std::uint64_t>() + value.get<std::uint64_t>();
            else if (mine.is_null()) mine = value;
        }
    }
};

}  // namespace rtlab::rtcore_sim
