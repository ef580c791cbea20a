#pragma once
// One RT core of the timing model: its queues, ray slots, scheduler, units, node cache and memory port, and
// the batch state it shares with the GPU level (docs/rtcore-model.md, "Timing model"). Methods: core_cycle.cpp.
#include <rtlab/core/ring_queue.hpp>
#include <rtlab/rtcore_sim/cache.hpp>
#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/rtcore_sim/scheduler.hpp>
#include <rtlab/rtcore_sim/stats.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>

#include "event_queue.hpp"
#include "stats_tree.hpp"
#include "unit_pool.hpp"

#include <cstdint>
#include <exception>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim {

// The batch or launch being simulated and what the cores share about it.
// Rays reach a core in submission groups: the rays one warp submits with one
// TraceRay instruction. A group's rays are consecutive in `rays`. In a tile
// batch (RtCore::run) every warp is one group; in a launch
// (RtCore::runLaunch) a warp's group k holds its threads' k-th rays, and
// group k+1 is ready shader.nextTraceLatency cycles after group k's last
// result (docs/rtcore-model.md, "Launches").
struct BatchState {
    std::span<const SimRay> rays;
    ProgrammableSide* side = nullptr;
    std::span<SimRayResult> results;            // per ray, or empty (a launch whose caller wants none)
    std::vector<std::uint32_t> raySteps;        // per ray (batch order): its traversal steps, once finished
    std::vector<std::uint32_t> groupFirst;      // per group: its first ray
    std::vector<std::uint32_t> groupSize;       // per group: its rays
    std::vector<std::uint32_t> groupWarp;       // per group: its warp
    std::vector<std::uint64_t> groupSubmit;     // per group: the cycle it entered the input queue
    std::vector<std::uint32_t> groupRemaining;  // per group: rays not yet returned
    std::vector<std::uint32_t> warpGroups;      // per warp w: its groups are [warpGroups[w], warpGroups[w + 1])
    std::vector<std::uint32_t> rayGroup;        // per ray: its group
    std::vector<std::uint32_t> warpLocal;       // per warp: its position in its core's warp list
    std::vector<RayTypeStats> rayTypes;         // over the whole GPU (a type's activity is a union over cores)
    std::uint32_t residentWarps = ~0u;          // warps resident per core at once (tile batches: all)
    std::uint32_t nextTraceLatency = 0;         // cycles from a group's last result to the warp's next group
    // A launch with gpu.rayOrder directionOrigin: each core admits the rays
    // waiting in its input queue in order of their key (rayKey, per ray).
    bool reorderInput = false;
    std::vector<std::uint64_t> rayKey;
    // A reordered batch (gpu.rayOrder, or a launch's groups): the batch's ray
    // i is the caller's ray order[i] (side callbacks get that index); `rays`
    // and `results` stay the caller's, read and written through ray(i) and
    // result(i) (no copies: a launch has millions of rays).
    std::vector<std::uint32_t> order;
    std::uint32_t sideIndex(std::uint32_t i) const { return order.empty() ? i : order[i]; }
    const SimRay& ray(std::uint32_t i) const { return rays[sideIndex(i)]; }
    SimRayResult& result(std::uint32_t i) const { return results[sideIndex(i)]; }
};

// ---------------------------------------------------------------------------
// One RT core: input queue, ray slots, scheduler, units, node cache (L1) and
// memory port. Its clock is the GPU's: the GPU runs every core's phases for
// a cycle, cores in index order, before moving on — or, in host-parallel
// epochs, every core's cycles of an epoch on its own (runEpoch), the L2
// answered between epochs. During a batch a core writes only its own state
// (its slots, its warps' results, its statistics): cores may run on
// different host threads. Aligned so that two cores share no cache line.

struct alignas(64) Core {
    // The small fields first: with the traversal state's header right after
    // them, a step touches a few consecutive cache lines of its slot.
    struct Slot {
        StepInfo step;
        std::uint32_t rayIndex = 0;
        std::uint32_t group = 0;
        std::uint64_t age = 0;
        std::uint64_t readyCycle = 0;  // became ready (waits for the scheduler from here)
        std::uint64_t admitCycle = 0;  // entered the ray slot
        std::uint64_t finishCycle = 0;
        std::uint32_t onChip = 0, spilled = 0;              // short stack model
        std::uint32_t spillEntries = 0, refillEntries = 0;  // of the step in flight
        std::uint32_t spills = 0, refills = 0;              // of the ray
        RayTraversal trav;                                  // ends with the (large) traversal stack
    };
    struct Delivery {
        std::uint32_t rayIndex;
        std::uint32_t group;
        std::uint64_t enterCycle;
    };

    const RtCoreConfig config;  // a copy: read on every step, never aliased by the counters
    const ModelScene& scene;
    const MemoryLayout& layout;
    BatchState& batch;
    NodeCache cache;
    MemoryPort port;
    UnitPool boxUnits, triangleUnits, transformUnits;
    std::unique_ptr<SchedulerPolicy> policy;
    bool policyUsesAddress = true;
    bool policyPrefetches = true;
    std::size_t readyCount = 0;  // rays held by the policy
    EventQueue events;
    std::vector<Slot> slots;
    std::vector<std::uint32_t> freeSlots;  // LIFO
    RingQueue<Delivery> completionQueue;
    RingQueue<std::uint32_t> blockedFinishers;  // finished rays waiting for a completion-queue entry (slots)
    std::uint64_t nextAge = 0;

    // This core's share of the batch: its warps (indices into the batch) in
    // order; at most batch.residentWarps of them resident at once, each in a
    // residency slot; groups ready to submit in the order they became ready.
    struct Resident {
        std::uint32_t warp = 0;
        std::uint32_t group = 0;  // its group being submitted or in flight
    };
    std::vector<std::uint32_t> warps;
    std::uint32_t nextWarp = 0;                 // the next of `warps` to become resident
    std::vector<Resident> resident;             // residency slots
    std::vector<std::uint32_t> freeResident;    // LIFO
    std::vector<std::uint32_t> residentOfWarp;  // per entry of `warps`: its residency slot
    RingQueue<std::uint32_t> readyGroups;       // groups waiting to enter the input queue
    std::vector<std::uint32_t> sequence;        // the core's rays in submission order
    std::uint32_t rayCount = 0, admitted = 0;   // rays of the core's warps; positions in `sequence`
    std::uint32_t delivered = 0;                // rays returned
    std::uint32_t submitted() const { return static_cast<std::uint32_t>(sequence.size()); }

    CoreStats stats;
    OccupancyTracker inputQueueOcc, slotOcc, readyOcc, completionOcc;
    std::vector<RayTypeWork> typeWork;  // per ray type, this batch
    std::vector<Activity> activity;     // this batch, in the core's order

    // The GPU loop's view of the core.
    static constexpr std::uint64_t kNever = ~std::uint64_t(0);
    std::uint64_t visit = 0;      // the next cycle the core may act in
    std::uint64_t lastVisit = 0;  // the last cycle it was simulated
    bool accountPending = false;  // accountUntil(lastVisit, next) still to do: next may move earlier
    bool deferring = false;       // L2 reads are deferred (host-parallel epochs, l2 mode cache)
    // Host-parallel epochs: the L2 reads of the current epoch and the fetches waiting for them.
    struct DeferredFetch {
        std::uint64_t seq;    // the fetch-done event's place among the core's events
        std::uint64_t cycle;  // issue cycle
        std::uint32_t slot;
        std::uint32_t firstTerm, terms;
    };
    DeferredReads deferredReads;
    std::vector<DeferredFetch> deferredFetches;
    std::uint64_t deferredReady = kNever;  // the earliest answer to deferredReads (once answered)
    std::exception_ptr error;              // a side callback threw in a host-parallel epoch
    std::uint64_t errorCycle = 0;

    Core(const RtCoreConfig& cfg, const ModelScene& s, const MemoryLayout& l, BatchState& b, SharedL2* l2);

    // The methods declared inline are called only in core_cycle.cpp and defined there, inline as they were
    // inside the class: GCC then folds more of a cycle into runEpoch (about 5 % fewer instructions per batch).
    static inline bool isBuiltinNonPrefetching(const std::string& name);
    inline void resetSlots();
    inline std::uint32_t rayAt(std::uint32_t k) const;

    // ---- addresses ----------------------------------------------------------
    inline MemoryRange stepRange(const StepInfo& st) const;
    inline std::uint64_t nextAddress(const Slot& s) const;

    // ---- the ray's life -----------------------------------------------------
    inline void makeReady(std::uint32_t slot, std::uint64_t c);
    inline void issue(std::uint32_t slot, std::uint64_t c);
    inline void fetchTimed(const LineFill& fetched, std::uint64_t c);
    void resolveDeferred();
    inline void onFetchDone(std::uint32_t slot, std::uint64_t c);
    inline void onStackTraffic(std::uint32_t slot, std::uint64_t c);
    inline void finish(std::uint32_t slot, std::uint64_t c);
    inline void enterCompletion(std::uint32_t slot, std::uint64_t c);
    inline void deliver(const Delivery& d, std::uint64_t c);
    inline void logActivity(std::uint64_t c, std::uint32_t rayType, std::int32_t delta);
    inline void groupDone(std::uint32_t group, std::uint64_t c);
    inline void becomeResident();

    // ---- one cycle -----------------------------------------------------------
    inline void processEvents(std::uint64_t c);
    inline void completion(std::uint64_t c);
    inline std::uint32_t pendingWarpSize() const;
    inline bool pendingWarpFits() const;
    inline void submission(std::uint64_t c);
    inline void admission(std::uint64_t c);
    inline void issueRays(std::uint64_t c);
    inline void cycle(std::uint64_t c);
    inline bool busy() const;
    inline void accountUntil(std::uint64_t c, std::uint64_t next);

    void beginBatch(std::size_t rayTypes);
    void addWarp(std::uint32_t warp);
    // After the warps are added: the first batch.residentWarps become resident (their first groups ready).
    void start();
    bool done() const { return delivered == rayCount; }

    // ---- the GPU loop --------------------------------------------------------
    void runEpoch(std::uint64_t end, bool everyCycle);
    void runEpochCatching(std::uint64_t end, bool everyCycle);
    void settle(bool everyCycle);

    void abortBatch(std::uint64_t now);
    void resetStats(std::uint64_t now);
    void resetTime();
    CoreSnapshot snapshot(std::uint64_t now) const;
};

}  // namespace rtlab::rtcore_sim
