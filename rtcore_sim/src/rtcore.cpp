// The event-driven timing model of the RT cores of a GPU (docs/rtcore-model.md,
// "Timing model", "GPU level"). The cores share one clock; every simulated
// cycle runs, for each core in index order, five phases in this order:
//   1. events due this cycle (fetch done -> unit, stack traffic, step done)
//   2. completion: up to completionPerCycle results leave the completion
//      queue; blocked finished rays move into the freed entries
//   3. submission: the next warp enters the input queue if it fits whole
//   4. admission: up to admitPerCycle rays move from the input queue into
//      free ray slots (and are ready at once)
//   5. issue: the scheduler issues up to issueWidth ready rays' next steps
// Cycles in which no core can do anything in phases 2-5 are skipped: the
// clock jumps to the next event of any core. Misses of a core's node cache go
// through its memory port and, in l2 mode cache, to the shared L2 and DRAM.
// With a side that allows concurrent callbacks the cores run in host-parallel
// epochs instead (simulate): same cycles and statistics, several threads.
#include <rtlab/core/error.hpp>
#include <rtlab/rtcore_sim/cache.hpp>
#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/rtcore_sim/scheduler.hpp>
#include <rtlab/rtcore_sim/stats.hpp>

#include "ray_order.hpp"

#include <rtlab/core/parallel.hpp>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <bit>
#include <deque>
#include <exception>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim {
namespace {

// ---------------------------------------------------------------------------
// Events: (slot, phase) in a timing wheel of kWheelSize cycles, farther ones
// in an overflow heap. Events of one cycle run in the order they were
// scheduled: every event carries its core's scheduling sequence number, and
// an event whose cycle is only known later (a fetch waiting for a deferred L2
// read, host-parallel epochs) takes its number when the serial model would
// have scheduled it (reserve()) and is inserted at its place (scheduleAt()).

enum Phase : std::uint32_t { kFetchDone = 0, kStackTraffic = 1, kStepDone = 2 };
constexpr std::uint32_t makeEvent(std::uint32_t slot, Phase phase) { return slot << 2 | phase; }

class EventWheel {
public:
    static constexpr std::uint64_t kSize = 4096;
    static constexpr unsigned kEventBits = 16;  // events are < 4 x 4096 (core.raySlots <= 4096)
    static constexpr std::uint64_t kEventMask = (std::uint64_t(1) << kEventBits) - 1;

    EventWheel() : buckets_(kSize) {}

    static std::uint32_t eventOf(std::uint64_t entry) { return static_cast<std::uint32_t>(entry & kEventMask); }

    void schedule(std::uint64_t cycle, std::uint32_t event) { scheduleAt(cycle, event, seq_++); }
    // A sequence number for an event scheduled later with scheduleAt.
    std::uint64_t reserve() { return seq_++; }
    void scheduleAt(std::uint64_t cycle, std::uint32_t event, std::uint64_t seq) {
        const std::uint64_t entry = seq << kEventBits | event;
        if (cycle - base_ < kSize) [[likely]] {  // also false for cycle < base_ (wraps around)
            place(cycle, entry);
        } else {
            scheduleFar(cycle, entry);
        }
    }
    // The window moves to [cycle, cycle + kSize); overflow events now inside
    // it join their buckets in (cycle, sequence) order.
    void advance(std::uint64_t cycle) {
        base_ = cycle;
        while (!overflow_.empty() && overflow_.front().cycle < base_ + kSize) {
            std::pop_heap(overflow_.begin(), overflow_.end(), Later{});
            const Far far = overflow_.back();
            overflow_.pop_back();
            place(far.cycle, far.entry);
        }
    }
    std::vector<std::uint64_t>& bucket(std::uint64_t cycle) { return buckets_[cycle & (kSize - 1)]; }
    void clearBucket(std::uint64_t cycle) {
        const std::size_t b = cycle & (kSize - 1);
        inWheel_ -= buckets_[b].size();
        buckets_[b].clear();
        bits_[b >> 6] &= ~(std::uint64_t(1) << (b & 63));
    }
    // The first cycle after `from` with an event; false when there is none.
    bool nextAfter(std::uint64_t from, std::uint64_t& out) const {
        if (inWheel_ > 0) {
            // Scan the bitmap from from+1, wrapping once around the wheel.
            for (std::uint64_t d = 1; d < kSize;) {
                const std::uint64_t c = from + d;
                const std::size_t b = c & (kSize - 1);
                const std::uint64_t word = bits_[b >> 6] >> (b & 63);
                if (word != 0) {
                    const std::uint64_t skip = static_cast<std::uint64_t>(std::countr_zero(word));
                    if (d + skip < kSize) {
                        out = c + skip;
                        return true;
                    }
                    break;
                }
                d += 64 - (b & 63);
            }
        }
        if (!overflow_.empty()) {
            out = overflow_.front().cycle;
            return true;
        }
        return false;
    }
    bool empty() const { return inWheel_ == 0 && overflow_.empty(); }
    [[gnu::noinline]] void scheduleFar(std::uint64_t cycle, std::uint64_t entry) {
        if (cycle < base_) throw std::logic_error("rtcore_sim: event scheduled in the past");
        overflow_.push_back(Far{cycle, entry});
        std::push_heap(overflow_.begin(), overflow_.end(), Later{});
    }
    void clear() {
        for (auto& b : buckets_) b.clear();
        bits_.fill(0);
        overflow_.clear();
        inWheel_ = 0;
    }

private:
    struct Far {
        std::uint64_t cycle, entry;
    };
    struct Later {
        bool operator()(const Far& a, const Far& b) const { return a.cycle != b.cycle ? a.cycle > b.cycle : a.entry > b.entry; }
    };
    // Entries of a bucket stay sorted by sequence number: new events append,
    // a deferred one is inserted at its place.
    void place(std::uint64_t cycle, std::uint64_t entry) {
        const std::size_t b = cycle & (kSize - 1);
        std::vector<std::uint64_t>& bucket = buckets_[b];
        if (bucket.empty() || bucket.back() < entry) [[likely]]
            bucket.push_back(entry);
        else
            bucket.insert(std::upper_bound(bucket.begin(), bucket.end(), entry), entry);
        bits_[b >> 6] |= std::uint64_t(1) << (b & 63);
        ++inWheel_;
    }

    std::vector<std::vector<std::uint64_t>> buckets_;
    std::array<std::uint64_t, kSize / 64> bits_{};
    std::vector<Far> overflow_;
    std::uint64_t base_ = 0;
    std::uint64_t seq_ = 0;
    std::size_t inWheel_ = 0;
};

// ---------------------------------------------------------------------------
// A pool of identical pipelined units: a request occupies one unit for
// `occupancy` issue cycles from start = max(request, unit free); its result
// is there at start + occupancy - 1 + latency. Requests arrive in cycle order
// and are served first come, first served by the earliest free unit.

struct UnitPool {
    std::vector<std::uint64_t> nextFree;
    std::uint32_t latency = 1;
    std::uint64_t requests = 0, busyCycles = 0, waitCycles = 0;

    UnitPool(std::uint32_t units, std::uint32_t lat) : nextFree(units, 0), latency(lat) {}
    struct Grant {
        std::uint64_t start, done;
    };
    Grant request(std::uint64_t now, std::uint32_t occupancy) {
        std::size_t best = 0;
        for (std::size_t i = 1; i < nextFree.size(); ++i)
            if (nextFree[i] < nextFree[best]) best = i;
        const std::uint64_t start = std::max(now, nextFree[best]);
        nextFree[best] = start + occupancy;
        ++requests;
        busyCycles += occupancy;
        waitCycles += start - now;
        return Grant{start, start + occupancy - 1 + latency};
    }
    void resetStats() { requests = busyCycles = waitCycles = 0; }
    void resetTime() { std::fill(nextFree.begin(), nextFree.end(), 0); }
};

std::uint32_t ceilDiv(std::uint32_t a, std::uint32_t b) { return (a + b - 1) / b; }

constexpr std::uint32_t kWorkHistogramBuckets = 256;
constexpr std::uint32_t kMaxRayTypes = 1024;

Histogram workHistogram() { return Histogram(Histogram::Scheme::Linear, kWorkHistogramBuckets); }

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
    X(warps) X(raysSubmitted) X(raysCompleted) X(inputQueue) X(scheduler) X(fetch) X(l2) X(dram) X(boxUnitWait)    \
    X(boxUnit) X(triangleUnitWait) X(triangleUnit) X(transformUnitWait) X(transformUnit) X(shader) X(stackRefill)    \
    X(completionBlocked) X(completionQueue) X(fetchBeyondHit) X(inputQueueFull) X(noFreeRaySlot)                     \
    X(completionQueueFull) X(issued) X(issueCycles) X(nodes) X(boxes) X(leaves) X(triangleTestCount)                 \
    X(proceduralTestCount) X(transforms) X(fetches) X(fetchBytes) X(anyHitCalls) X(intersectionCalls) X(pushes)      \
    X(pops) X(spilledEntries) X(spillWrites) X(refills) X(refilledEntries) X(warpsCompleted) X(warpSteps)            \
    X(warpLanes) X(raySteps)
#define RTCORE_SIM_CORE_HISTOGRAMS(X)                                                                                \
    X(latency) X(steps) X(nodeVisits) X(leafVisits) X(boxTests) X(triangleTests) X(proceduralTests)                  \
    X(instanceTransitions) X(maxStackDepth) X(activeRaysPerWarpStep)

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
            else if (mine.is_null())
                mine = value;
        }
    }
};

// The batch being simulated and what the cores share about it.
struct BatchState {
    std::span<const SimRay> rays;
    ProgrammableSide* side = nullptr;
    std::span<SimRayResult> results;
    std::vector<std::uint64_t> warpSubmit;
    std::vector<std::uint32_t> warpLocal;  // per warp: its position in its core's warp list
    std::vector<RayTypeStats> rayTypes;    // over the whole GPU (a type's activity is a union over cores)
    // gpu.rayOrder other than submission: rays/results above are the reordered
    // copies; order[i] = index in the caller's batch (side callbacks get it).
    std::vector<std::uint32_t> order;
    std::uint32_t sideIndex(std::uint32_t i) const { return order.empty() ? i : order[i]; }
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
        std::uint32_t warp = 0;
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
    EventWheel wheel;
    std::vector<Slot> slots;
    std::vector<std::uint32_t> freeSlots;  // LIFO
    std::deque<Delivery> completionQueue;
    std::deque<std::uint32_t> blockedFinishers;  // finished rays waiting for a completion-queue entry (slots)
    std::uint64_t nextAge = 0;

    // This core's share of the batch: its warps (indices into the batch) in order.
    std::vector<std::uint32_t> warps;
    std::vector<std::uint32_t> warpRemaining;  // per entry of `warps`: rays not yet returned
    std::uint32_t rayCount = 0, submitted = 0, admitted = 0;  // positions in the core's ray sequence
    std::uint32_t delivered = 0;                              // rays returned

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
    std::exception_ptr error;  // a side callback threw in a host-parallel epoch
    std::uint64_t errorCycle = 0;

    Core(const RtCoreConfig& cfg, const ModelScene& s, const MemoryLayout& l, BatchState& b, SharedL2* l2)
        : config(cfg), scene(s), layout(l), batch(b), cache(cfg.cache),
          port(cfg.memory, l2, cfg.l2.hitLatency), boxUnits(cfg.traversal.units, cfg.traversal.latency),
          triangleUnits(cfg.triangle.units, cfg.triangle.latency),
          transformUnits(cfg.transform.units, cfg.transform.latency), policy(makeSchedulerPolicy(cfg.scheduler)),
          slots(cfg.core.raySlots), inputQueueOcc(cfg.core.inputQueueRays), slotOcc(cfg.core.raySlots),
          readyOcc(cfg.core.raySlots), completionOcc(cfg.core.completionQueueRays) {
        policyUsesAddress = policy->usesAddress();
        policyPrefetches = !isBuiltinNonPrefetching(cfg.scheduler.policy);  // saves a virtual call per cycle
        resetSlots();
    }

    static bool isBuiltinNonPrefetching(const std::string& name) {
        return name == "fifo" || name == "oldestFirst" || name == "treelet";
    }

    void resetSlots() {
        freeSlots.clear();
        for (std::uint32_t i = static_cast<std::uint32_t>(slots.size()); i-- > 0;) freeSlots.push_back(i);
    }

    // The batch index of the k-th ray of this core's sequence.
    std::uint32_t rayAt(std::uint32_t k) const {
        const std::uint32_t w = config.core.warpWidth;
        return warps[k / w] * w + k % w;
    }

    // ---- addresses ----------------------------------------------------------

    MemoryRange stepRange(const StepInfo& st) const {
        switch (st.kind) {
            case StepKind::Instance: return layout.instance(st.index);
            case StepKind::TlasLeaf: return layout.tlasLeaf(scene.tlas().leaves[st.index], st.index);
            case StepKind::BlasLeaf:
                return layout.blasLeaf(st.mesh, scene.blas(st.mesh)->bvh.leaves[st.index], st.index);
            case StepKind::Node: return st.tlas ? layout.tlasNode(st.index) : layout.blasNode(st.mesh, st.index);
        }
        return {};
    }
    std::uint64_t nextAddress(const Slot& s) const {
        const StackEntry& e = s.trav.next();
        if (e.kind == EntryKind::Instance) return layout.instance(e.refBits).address;
        const NodeRef ref = e.ref();
        if (e.kind == EntryKind::TlasRef)
            return ref.isNode() ? layout.tlasNode(ref.index()).address
                                : layout.tlasLeaf(scene.tlas().leaves[ref.index()], ref.index()).address;
        const std::uint32_t mesh = s.trav.currentMesh();
        return ref.isNode() ? layout.blasNode(mesh, ref.index()).address
                            : layout.blasLeaf(mesh, scene.blas(mesh)->bvh.leaves[ref.index()], ref.index()).address;
    }

    // ---- the ray's life -----------------------------------------------------

    void makeReady(std::uint32_t slot, std::uint64_t c) {
        Slot& s = slots[slot];
        s.readyCycle = c;
        if (s.trav.finished()) return finish(slot, c);
        policy->push(ReadyRay{slot, s.age, policyUsesAddress ? nextAddress(s) : 0});
        readyOcc.set(++readyCount, c);
    }

    void issue(std::uint32_t slot, std::uint64_t c) {
        Slot& s = slots[slot];
        stats.scheduler += c - s.readyCycle;
        StepInfo& st = s.step;
        s.trav.step(*batch.side, batch.sideIndex(s.rayIndex), st);

        // Step: the short stack — pushes spill the bottom entries once it is
        // full, pops from an empty short stack refill from memory.
        const std::uint32_t capacity = config.stack.shortStackEntries;
        const std::uint32_t direct = std::min(st.pushes, capacity - s.onChip);
        s.onChip += direct;
        s.spillEntries = st.pushes - direct;
        s.spilled += s.spillEntries;
        s.refillEntries = 0;
        for (std::uint32_t p = 0; p < st.pops; ++p) {
            if (s.onChip == 0) {
                const std::uint32_t k = std::min(s.spilled, config.stack.refillEntries);
                s.spilled -= k;
                s.onChip += k;
                s.refillEntries += k;
                ++s.refills;
                ++stats.refills;
            }
            --s.onChip;
        }
        if (s.trav.finished()) s.onChip = s.spilled = 0;  // AcceptHitAndEndSearch discards the stack
        s.spills += s.spillEntries;
        stats.pushes += st.pushes;
        stats.pops += st.pops;
        stats.spilledEntries += s.spillEntries;
        stats.refilledEntries += s.refillEntries;

        // Step: fetch the node, leaf or instance through the node cache (and
        // below it the port, the L2 and DRAM).
        const MemoryRange range = stepRange(st);
        const LineFill fetched = cache.fetch(range, c, port);
        ++stats.fetches;
        stats.fetchBytes += range.bytes;
        if (isDeferred(fetched.ready)) [[unlikely]] {
            // It waits for an L2 read answered after this epoch: its time and
            // event follow then (resolveDeferred), its event in this place.
            deferredFetches.push_back(DeferredFetch{wheel.reserve(), c, slot,
                                                    static_cast<std::uint32_t>(fetched.ready & kDeferredIndex),
                                                    static_cast<std::uint32_t>(fetched.l2Cycles)});
            return;
        }
        fetchTimed(fetched, c);
        wheel.schedule(fetched.ready, makeEvent(slot, kFetchDone));
    }

    // The latency breakdown's terms of a fetch issued at c.
    void fetchTimed(const LineFill& fetched, std::uint64_t c) {
        const std::uint64_t waited = fetched.ready - c;
        stats.fetch += waited - fetched.l2Cycles - fetched.dramCycles;
        stats.l2 += fetched.l2Cycles;
        stats.dram += fetched.dramCycles;
        stats.fetchBeyondHit += waited > config.cache.hitLatency ? waited - config.cache.hitLatency : 0;
    }

    // Between epochs, the epoch's L2 reads answered (deferredReads.fills):
    // the node cache gets the fill cycles, each waiting fetch its time,
    // statistics and fetch-done event.
    void resolveDeferred() {
        if (deferredReads.empty()) return;
        cache.resolve(deferredReads);
        for (const DeferredFetch& f : deferredFetches) {
            const LineFill fetched = cache.evaluate(f.cycle, deferredReads.terms.data() + f.firstTerm, f.terms, deferredReads);
            fetchTimed(fetched, f.cycle);
            wheel.scheduleAt(fetched.ready, makeEvent(f.slot, kFetchDone), f.seq);
        }
        deferredFetches.clear();
        deferredReads.clear();
        deferredReady = kNever;
    }

    void onFetchDone(std::uint32_t slot, std::uint64_t c) {
        Slot& s = slots[slot];
        const StepInfo& st = s.step;
        std::uint64_t t = c;
        // Step: the step's unit.
        switch (st.kind) {
            case StepKind::Node: {
                const auto g = boxUnits.request(c, ceilDiv(st.boxTests, config.traversal.boxesPerCycle));
                stats.boxUnitWait += g.start - c;
                stats.boxUnit += g.done - g.start;
                ++stats.nodes;
                stats.boxes += st.boxTests;
                t = g.done;
                break;
            }
            case StepKind::BlasLeaf: {
                ++stats.leaves;
                if (st.primitiveTests == 0) break;
                const auto g = triangleUnits.request(c, ceilDiv(st.primitiveTests, config.triangle.testsPerCycle));
                stats.triangleUnitWait += g.start - c;
                stats.triangleUnit += g.done - g.start;
                t = g.done;
                break;
            }
            case StepKind::Instance: {
                const auto g = transformUnits.request(c, 1);
                stats.transformUnitWait += g.start - c;
                stats.transformUnit += g.done - g.start;
                ++stats.transforms;
                t = g.done;
                break;
            }
            case StepKind::TlasLeaf: break;  // mask tests only
        }
        // Step: shader round trips, one after the other.
        const std::uint64_t shaderCycles = std::uint64_t(st.anyHitCalls) * config.shader.anyHitLatency +
                                           std::uint64_t(st.intersectionCalls) * config.shader.intersectionLatency;
        stats.anyHitCalls += st.anyHitCalls;
        stats.intersectionCalls += st.intersectionCalls;
        stats.shader += shaderCycles;
        t += shaderCycles;
        wheel.schedule(t, makeEvent(slot, s.spillEntries || s.refillEntries ? kStackTraffic : kStepDone));
    }

    void onStackTraffic(std::uint32_t slot, std::uint64_t c) {
        Slot& s = slots[slot];
        // Spills are writes (they occupy the port, nobody waits); the step's
        // refills are one read the ray waits for.
        if (s.spillEntries) {
            port.writeStack(c, s.spillEntries * config.stack.entryBytes);
            ++stats.spillWrites;
        }
        std::uint64_t r = c;
        if (s.refillEntries) r = port.readStack(c, s.refillEntries * config.stack.entryBytes);
        stats.stackRefill += r - c;
        wheel.schedule(r, makeEvent(slot, kStepDone));
    }

    void finish(std::uint32_t slot, std::uint64_t c) {
        Slot& s = slots[slot];
        s.finishCycle = c;
        SimRayResult& r = batch.results[s.rayIndex];
        r.hit = s.trav.hit();
        r.work = s.trav.counters();
        r.stackSpills = s.spills;
        r.stackRefills = s.refills;
        r.slotCycles = static_cast<std::uint32_t>(std::min<std::uint64_t>(c - s.admitCycle, UINT32_MAX));
        const TraversalCounters& w = r.work;
        stats.steps.add(w.steps);
        stats.nodeVisits.add(w.nodeVisits);
        stats.leafVisits.add(w.leafVisits);
        stats.boxTests.add(w.boxTests);
        stats.triangleTests.add(w.triangleTests);
        stats.proceduralTests.add(w.proceduralTests);
        stats.instanceTransitions.add(w.instanceTransitions);
        stats.maxStackDepth.add(w.maxStackDepth);
        stats.triangleTestCount += w.triangleTests;
        stats.proceduralTestCount += w.proceduralTests;
        RayTypeWork& type = typeWork[batch.rays[s.rayIndex].rayType];
        type.nodeVisits += w.nodeVisits;
        type.triangleTests += w.triangleTests;
        type.instanceTransitions += w.instanceTransitions;
        if (completionQueue.size() < config.core.completionQueueRays) enterCompletion(slot, c);
        else blockedFinishers.push_back(slot);
    }

    void enterCompletion(std::uint32_t slot, std::uint64_t c) {
        Slot& s = slots[slot];
        stats.completionBlocked += c - s.finishCycle;
        completionQueue.push_back(Delivery{s.rayIndex, c});
        completionOcc.set(completionQueue.size(), c);
        freeSlots.push_back(slot);
        slotOcc.set(slots.size() - freeSlots.size(), c);
    }

    void deliver(const Delivery& d, std::uint64_t c) {
        const std::uint32_t warp = d.rayIndex / config.core.warpWidth;
        const std::uint64_t latency = c - batch.warpSubmit[warp];
        stats.completionQueue += c - d.enterCycle;
        batch.results[d.rayIndex].cycles = static_cast<std::uint32_t>(std::min<std::uint64_t>(latency, UINT32_MAX));
        stats.latency.add(latency);
        ++stats.raysCompleted;
        const std::uint32_t rayType = batch.rays[d.rayIndex].rayType;
        RayTypeWork& type = typeWork[rayType];
        ++type.rays;
        type.latency.add(latency);
        logActivity(c, rayType, -1);
        ++delivered;
        if (--warpRemaining[batch.warpLocal[warp]] == 0) warpDone(warp);
    }

    void logActivity(std::uint64_t c, std::uint32_t rayType, std::int32_t delta) {
        if (!activity.empty()) {
            Activity& last = activity.back();
            if (last.cycle == c && last.type == rayType && (last.delta > 0) == (delta > 0)) {
                last.delta += delta;
                return;
            }
        }
        activity.push_back(Activity{c, rayType, delta});
    }

    // SIMD efficiency of a lockstep traversal of this warp: warp step k has
    // the rays with more than k steps active.
    void warpDone(std::uint32_t warp) {
        const std::uint32_t width = config.core.warpWidth;
        const std::uint32_t first = warp * width;
        const std::uint32_t last = std::min<std::uint32_t>(first + width, static_cast<std::uint32_t>(batch.rays.size()));
        std::array<std::uint32_t, 64> steps;
        const std::uint32_t m = last - first;
        for (std::uint32_t i = 0; i < m; ++i) steps[i] = batch.results[first + i].work.steps;
        std::sort(steps.begin(), steps.begin() + m);
        std::uint32_t previous = 0;
        for (std::uint32_t j = 0; j < m; ++j) {
            stats.raySteps += steps[j];
            if (steps[j] > previous) {
                stats.activeRaysPerWarpStep.add(m - j, steps[j] - previous);
                previous = steps[j];
            }
        }
        ++stats.warpsCompleted;
        stats.warpSteps += previous;
        stats.warpLanes += std::uint64_t(width) * previous;
    }

    // ---- one cycle -----------------------------------------------------------

    void processEvents(std::uint64_t c) {
        std::vector<std::uint64_t>& bucket = wheel.bucket(c);
        for (std::size_t i = 0; i < bucket.size(); ++i) {  // handlers may append events for this cycle
            const std::uint32_t event = EventWheel::eventOf(bucket[i]);
            const std::uint32_t slot = event >> 2;
            switch (static_cast<Phase>(event & 3)) {
                case kFetchDone: onFetchDone(slot, c); break;
                case kStackTraffic: onStackTraffic(slot, c); break;
                case kStepDone: makeReady(slot, c); break;
            }
        }
        wheel.clearBucket(c);
    }

    void completion(std::uint64_t c) {
        for (std::uint32_t k = 0; k < config.core.completionPerCycle && !completionQueue.empty(); ++k) {
            const Delivery d = completionQueue.front();
            completionQueue.pop_front();
            deliver(d, c);
        }
        while (!blockedFinishers.empty() && completionQueue.size() < config.core.completionQueueRays) {
            const std::uint32_t slot = blockedFinishers.front();
            blockedFinishers.pop_front();
            enterCompletion(slot, c);
        }
        completionOcc.set(completionQueue.size(), c);
    }

    std::uint32_t pendingWarpSize() const {
        const std::uint32_t first = warps[submitted / config.core.warpWidth] * config.core.warpWidth;
        return std::min<std::uint32_t>(config.core.warpWidth, static_cast<std::uint32_t>(batch.rays.size()) - first);
    }
    bool pendingWarpFits() const {
        return submitted < rayCount && config.core.inputQueueRays - (submitted - admitted) >= pendingWarpSize();
    }

    void submission(std::uint64_t c) {
        if (submitted == rayCount) return;
        if (!pendingWarpFits()) {
            ++stats.inputQueueFull;
            return;
        }
        const std::uint32_t size = pendingWarpSize();
        const std::uint32_t warp = warps[submitted / config.core.warpWidth];
        batch.warpSubmit[warp] = c;
        for (std::uint32_t i = warp * config.core.warpWidth; i < warp * config.core.warpWidth + size; ++i)
            logActivity(c, batch.rays[i].rayType, +1);
        submitted += size;
        ++stats.warps;
        stats.raysSubmitted += size;
        inputQueueOcc.set(submitted - admitted, c);
    }

    void admission(std::uint64_t c) {
        for (std::uint32_t k = 0; k < config.core.admitPerCycle && admitted < submitted && !freeSlots.empty(); ++k) {
            const std::uint32_t slot = freeSlots.back();
            freeSlots.pop_back();
            Slot& s = slots[slot];
            s.rayIndex = rayAt(admitted++);
            s.warp = s.rayIndex / config.core.warpWidth;
            s.age = nextAge++;
            s.admitCycle = c;
            s.onChip = s.spilled = s.spills = s.refills = 0;
            s.trav.begin(scene, batch.rays[s.rayIndex]);
            stats.inputQueue += c - batch.warpSubmit[s.warp];
            slotOcc.set(slots.size() - freeSlots.size(), c);
            makeReady(slot, c);
        }
        inputQueueOcc.set(submitted - admitted, c);
    }

    void issueRays(std::uint64_t c) {
        std::uint32_t issuedNow = 0;
        ReadyRay r;
        while (readyCount > 0 && issuedNow < config.scheduler.issueWidth && policy->pop(r)) {
            --readyCount;
            issue(r.slot, c);
            ++issuedNow;
        }
        if (issuedNow) {
            stats.issued += issuedNow;
            ++stats.issueCycles;
            readyOcc.set(readyCount, c);
        }
        // Prefetches the policy asked for, after this cycle's demand fetches.
        if (policyPrefetches) {
            PrefetchRequest p;
            while (policy->takePrefetch(p)) cache.prefetch(MemoryRange{p.address, p.bytes}, c, port);
        }
    }

    // The five phases of cycle c.
    void cycle(std::uint64_t c) {
        processEvents(c);
        completion(c);
        submission(c);
        admission(c);
        issueRays(c);
    }
    // Whether one of phases 2-5 can act in the next cycle.
    bool busy() const {
        return readyCount > 0 || !completionQueue.empty() || (admitted < submitted && !freeSlots.empty()) ||
               pendingWarpFits();
    }
    // Conditions that hold through the cycles after c up to next (exclusive), skipped or not.
    void accountUntil(std::uint64_t c, std::uint64_t next) {
        if (submitted < rayCount && !pendingWarpFits()) stats.inputQueueFull += next - c - 1;
        if (admitted < submitted && freeSlots.empty()) stats.noFreeRaySlot += next - c;
        if (!blockedFinishers.empty()) stats.completionQueueFull += next - c;
    }

    void beginBatch(std::size_t rayTypes) {
        warps.clear();
        warpRemaining.clear();
        rayCount = submitted = admitted = delivered = 0;
        if (typeWork.size() < rayTypes) typeWork.resize(rayTypes);
        activity.clear();
        deferredReads.clear();
        deferredFetches.clear();
        deferredReady = kNever;
        error = nullptr;
    }
    // Returns the warp's position in this core's list.
    std::uint32_t addWarp(std::uint32_t warp, std::uint32_t size) {
        warps.push_back(warp);
        warpRemaining.push_back(size);
        rayCount += size;
        return static_cast<std::uint32_t>(warps.size() - 1);
    }
    bool done() const { return delivered == rayCount; }

    // ---- the GPU loop --------------------------------------------------------

    // Simulates this core's active cycles before `end` (from `visit`). It
    // stops for good once all its rays are returned (nothing is left to
    // happen). The accounting of skipped cycles up to the next active cycle
    // is done here when that cycle is before `end`, otherwise left to
    // settle() (a deferred fetch may make it earlier).
    void runEpoch(std::uint64_t end, bool everyCycle) {
        while (visit < end) {
            const std::uint64_t c = visit;
            wheel.advance(c);
            cycle(c);
            lastVisit = c;
            if (done()) {
                visit = kNever;
                return;
            }
            std::uint64_t n = c + 1;
            if (!busy() && !everyCycle && !wheel.nextAfter(c, n)) n = kNever;
            visit = n;
            if (n < end) {
                accountUntil(c, n);
                continue;
            }
            if (deferring) {
                accountPending = true;  // a fetch of this epoch may bring the next active cycle forward
                return;
            }
            if (n != kNever) accountUntil(c, n);
            return;
        }
    }
    // The same, catching a side callback's exception (host-parallel epochs:
    // the other cores finish the epoch; the GPU rethrows afterwards).
    void runEpochCatching(std::uint64_t end, bool everyCycle) {
        try {
            runEpoch(end, everyCycle);
        } catch (...) {
            error = std::current_exception();
            errorCycle = lastVisit = visit;
            visit = kNever;
            accountPending = false;
        }
    }
    // After the epoch's L2 reads are resolved: the next active cycle and the
    // accounting of the cycles skipped until then.
    void settle(bool everyCycle) {
        if (!accountPending) return;
        accountPending = false;
        const std::uint64_t c = lastVisit;
        std::uint64_t n = c + 1;
        if (!busy() && !everyCycle && !wheel.nextAfter(c, n)) n = kNever;
        if (n != kNever) accountUntil(c, n);
        visit = n;
    }

    // A side callback threw: drop the batch's rays.
    void abortBatch(std::uint64_t now) {
        deferredFetches.clear();
        deferredReads.clear();
        deferredReady = kNever;
        wheel.clear();
        policy = makeSchedulerPolicy(config.scheduler);
        readyCount = 0;
        completionQueue.clear();
        blockedFinishers.clear();
        resetSlots();
        beginBatch(typeWork.size());
        inputQueueOcc.set(0, now);
        slotOcc.set(0, now);
        readyOcc.set(0, now);
        completionOcc.set(0, now);
    }

    void resetStats(std::uint64_t now) {
        stats = CoreStats{};
        boxUnits.resetStats();
        triangleUnits.resetStats();
        transformUnits.resetStats();
        cache.resetStats();
        cache.invalidations = 0;
        port.channel.resetStats();
        policy->resetStats();
        inputQueueOcc.reset(now);
        slotOcc.reset(now);
        readyOcc.reset(now);
        completionOcc.reset(now);
    }

    void resetTime() {
        nextAge = 0;
        deferredFetches.clear();
        deferredReads.clear();
        deferredReady = kNever;
        wheel.clear();
        wheel.advance(0);
        cache.invalidate();
        port.channel.resetTime();
        boxUnits.resetTime();
        triangleUnits.resetTime();
        transformUnits.resetTime();
    }

    CoreSnapshot snapshot(std::uint64_t now) const {
        CoreSnapshot s;
        s.stats = stats;
        s.box = UnitCounters{boxUnits.requests, boxUnits.busyCycles, boxUnits.waitCycles};
        s.triangle = UnitCounters{triangleUnits.requests, triangleUnits.busyCycles, triangleUnits.waitCycles};
        s.transform = UnitCounters{transformUnits.requests, transformUnits.busyCycles, transformUnits.waitCycles};
        s.cacheAccesses = cache.accesses;
        s.cacheHits = cache.hits;
        s.cachePendingHits = cache.pendingHits;
        s.cacheMisses = cache.misses;
        s.cacheEvictions = cache.evictions;
        s.cacheInvalidations = cache.invalidations;
        s.prefetchRequests = cache.prefetchRequests;
        s.prefetchLines = cache.prefetchLines;
        s.prefetchHits = cache.prefetchHits;
        const MemoryChannel& m = port.channel;
        s.memReads = m.reads;
        s.memReadBytes = m.readBytes;
        s.memWrites = m.writes;
        s.memWriteBytes = m.writeBytes;
        s.memBusy = m.busyCycles;
        s.memQueue = m.queueCycles;
        s.inputQueueOcc = inputQueueOcc.histogram(now);
        s.slotOcc = slotOcc.histogram(now);
        s.readyOcc = readyOcc.histogram(now);
        s.completionOcc = completionOcc.histogram(now);
        policy->addStats(s.policyStats);
        return s;
    }
};

// The stats tree of one core, or of `cores` cores merged: counters are sums;
// unit counts are totals; capacities, slot counts, widths and occupancy
// levels are per core, occupancy weights are core-cycles.
nlohmann::json coreTreeJson(const CoreSnapshot& snap, const RtCoreConfig& config, std::uint32_t cores,
                            std::uint64_t cycles, std::uint64_t batches) {
    using nlohmann::json;
    const CoreStats& stats = snap.stats;
    const auto rate = [](double a, double b) { return b > 0.0 ? a / b : 0.0; };
    const auto unitJson = [&](const UnitCounters& u, std::uint32_t perCore) {
        const std::uint32_t count = perCore * cores;
        json j;
        j["units"] = count;
        j["requests"] = u.requests;
        j["busyCycles"] = u.busyCycles;
        j["waitCycles"] = u.waitCycles;
        j["utilization"] = rate(double(u.busyCycles), double(cycles) * count);
        return j;
    };

    json out;
    out["frame"] = {{"cycles", cycles},
                    {"batches", batches},
                    {"rays", stats.raysCompleted},
                    {"raysPerCycle", rate(double(stats.raysCompleted), double(cycles))}};

    json raysJson;
    raysJson["submitted"] = stats.raysSubmitted;
    raysJson["completed"] = stats.raysCompleted;
    raysJson["latency"] = stats.latency.toJson();
    raysJson["steps"] = stats.steps.toJson();
    raysJson["nodeVisits"] = stats.nodeVisits.toJson();
    raysJson["leafVisits"] = stats.leafVisits.toJson();
    raysJson["boxTests"] = stats.boxTests.toJson();
    raysJson["triangleTests"] = stats.triangleTests.toJson();
    raysJson["proceduralTests"] = stats.proceduralTests.toJson();
    raysJson["instanceTransitions"] = stats.instanceTransitions.toJson();
    raysJson["maxStackDepth"] = stats.maxStackDepth.toJson();
    raysJson["latencyBreakdown"] = {{"inputQueue", stats.inputQueue},
                                    {"scheduler", stats.scheduler},
                                    {"fetch", stats.fetch},
                                    {"l2", stats.l2},
                                    {"dram", stats.dram},
                                    {"boxUnitWait", stats.boxUnitWait},
                                    {"boxUnit", stats.boxUnit},
                                    {"triangleUnitWait", stats.triangleUnitWait},
                                    {"triangleUnit", stats.triangleUnit},
                                    {"transformUnitWait", stats.transformUnitWait},
                                    {"transformUnit", stats.transformUnit},
                                    {"shader", stats.shader},
                                    {"stackRefill", stats.stackRefill},
                                    {"completionBlocked", stats.completionBlocked},
                                    {"completionQueue", stats.completionQueue}};
    out["rays"] = std::move(raysJson);

    out["submission"] = {{"warpWidth", config.core.warpWidth},
                         {"warps", stats.warps},
                         {"blockedCycles", {{"inputQueueFull", stats.inputQueueFull}}},
                         {"inputQueue", {{"capacity", config.core.inputQueueRays}, {"occupancy", snap.inputQueueOcc.toJson()}}}};
    out["raySlots"] = {{"count", config.core.raySlots},
                       {"occupancy", snap.slotOcc.toJson()},
                       {"utilization", rate(snap.slotOcc.mean(), double(config.core.raySlots))},
                       {"blockedCycles", {{"noFreeRaySlot", stats.noFreeRaySlot}}}};

    json sched = snap.policyStats;
    sched["policy"] = config.scheduler.policy;
    sched["issueWidth"] = config.scheduler.issueWidth;
    sched["issued"] = stats.issued;
    sched["issueCycles"] = stats.issueCycles;
    sched["utilization"] = rate(double(stats.issued), double(cycles) * (config.scheduler.issueWidth * cores));
    sched["readyRays"] = snap.readyOcc.toJson();
    sched["waitCycles"] = stats.scheduler;
    out["scheduler"] = std::move(sched);

    json traversal = unitJson(snap.box, config.traversal.units);
    traversal["nodes"] = stats.nodes;
    traversal["boxTests"] = stats.boxes;
    out["traversalUnits"] = std::move(traversal);
    json triangle = unitJson(snap.triangle, config.triangle.units);
    triangle["leaves"] = stats.leaves;
    triangle["triangleTests"] = stats.triangleTestCount;
    triangle["proceduralTests"] = stats.proceduralTestCount;
    out["triangleUnits"] = std::move(triangle);
    json transform = unitJson(snap.transform, config.transform.units);
    transform["transforms"] = stats.transforms;
    out["transformUnits"] = std::move(transform);
    out["shader"] = {{"anyHitCalls", stats.anyHitCalls},
                     {"intersectionCalls", stats.intersectionCalls},
                     {"cycles", stats.shader}};
    out["stack"] = {{"shortStackEntries", config.stack.shortStackEntries},
                    {"pushes", stats.pushes},
                    {"pops", stats.pops},
                    {"spilledEntries", stats.spilledEntries},
                    {"spillWrites", stats.spillWrites},
                    {"refills", stats.refills},
                    {"refilledEntries", stats.refilledEntries},
                    {"spillBytes", stats.spilledEntries * config.stack.entryBytes},
                    {"refillBytes", stats.refilledEntries * config.stack.entryBytes}};
    out["cache"] = {{"sizeBytes", config.cache.sizeBytes},
                    {"fetches", stats.fetches},
                    {"fetchBytes", stats.fetchBytes},
                    {"accesses", snap.cacheAccesses},
                    {"hits", snap.cacheHits},
                    {"pendingHits", snap.cachePendingHits},
                    {"misses", snap.cacheMisses},
                    {"evictions", snap.cacheEvictions},
                    {"invalidations", snap.cacheInvalidations},
                    {"hitRate", rate(double(snap.cacheHits), double(snap.cacheAccesses))}};
    if (snap.prefetchRequests > 0)  // only policies that prefetch (treeletPrefetch)
        out["cache"]["prefetch"] = {{"requests", snap.prefetchRequests},
                                    {"lines", snap.prefetchLines},
                                    {"usefulLines", snap.prefetchHits},
                                    {"accuracy", rate(double(snap.prefetchHits), double(snap.prefetchLines))}};
    out["memory"] = {{"reads", snap.memReads},
                     {"readBytes", snap.memReadBytes},
                     {"writes", snap.memWrites},
                     {"writeBytes", snap.memWriteBytes},
                     {"busyCycles", snap.memBusy},
                     {"queueCycles", snap.memQueue},
                     {"utilization", rate(double(snap.memBusy), double(cycles) * cores)},
                     {"bytesPerCycle", rate(double(snap.memReadBytes + snap.memWriteBytes), double(cycles))}};
    out["completion"] = {{"capacity", config.core.completionQueueRays},
                         {"occupancy", snap.completionOcc.toJson()},
                         {"blockedCycles", {{"completionQueueFull", stats.completionQueueFull}}}};
    out["stalls"] = {{"blockedCycles",
                      {{"inputQueueFull", stats.inputQueueFull},
                       {"noFreeRaySlot", stats.noFreeRaySlot},
                       {"completionQueueFull", stats.completionQueueFull}}},
                     {"rayCycles",
                      {{"inputQueue", stats.inputQueue},
                       {"scheduler", stats.scheduler},
                       {"cacheMissAndMemory", stats.fetchBeyondHit},
                       {"boxUnitBusy", stats.boxUnitWait},
                       {"triangleUnitBusy", stats.triangleUnitWait},
                       {"transformUnitBusy", stats.transformUnitWait},
                       {"shaderRoundTrip", stats.shader},
                       {"stackRefill", stats.stackRefill},
                       {"completionQueueFull", stats.completionBlocked},
                       {"completionQueue", stats.completionQueue}}}};
    out["simd"] = {{"warps", stats.warpsCompleted},
                   {"warpSteps", stats.warpSteps},
                   {"raySteps", stats.raySteps},
                   {"activeRaysPerWarpStep", stats.activeRaysPerWarpStep.toJson()},
                   {"efficiency", rate(double(stats.raySteps), double(stats.warpLanes))},
                   {"laneFill", rate(double(stats.raysCompleted), double(stats.warpsCompleted) * config.core.warpWidth)}};
    return out;
}

}  // namespace

// ---------------------------------------------------------------------------
// The GPU: cores in lock step on one clock, the shared L2 and DRAM.

struct RtCore::Impl {
    RtCoreConfig config;
    const ModelScene& scene;
    MemoryLayout layout;
    std::uint64_t layoutGeneration = ~std::uint64_t(0);
    BatchState batch;
    std::vector<SimRay> orderedRays;  // the batch in gpu.rayOrder (when not submission)
    std::vector<SimRayResult> orderedResults;
    std::unique_ptr<SharedL2> l2;  // l2 mode cache only
    std::vector<std::unique_ptr<Core>> cores;
    std::vector<std::size_t> cursor;  // scratch: per core, a position in its log (mergeByCycle)
    struct alignas(64) L2Group {  // one host thread's share of answering L2 reads (answerL2Reads)
        L2Counters counters;
        std::uint64_t stamp = 0;
        std::vector<std::uint64_t> ready;  // per core: the earliest answer to its reads
        std::vector<std::size_t> cursor;
    };
    std::vector<L2Group> l2Groups;
    bool everyCycle = false;  // debug: visit every cycle instead of jumping to the next event
    std::uint64_t now = 0;    // the clock between batches
    std::uint64_t clock = 0;  // the cycle being simulated during a batch
    std::uint64_t frameStart = 0, batches = 0;

    Impl(const RtCoreConfig& cfg, const ModelScene& s) : config(cfg), scene(s) {
        if (config.l2.mode == L2Mode::Cache) l2 = std::make_unique<SharedL2>(config.l2, config.dram);
        for (std::uint32_t k = 0; k < config.gpu.cores; ++k)
            cores.push_back(std::make_unique<Core>(config, scene, layout, batch, l2.get()));
    }

    // The dispatch rule: which core each warp of the batch goes to.
    void dispatch(std::uint32_t warpCount) {
        const std::uint32_t n = static_cast<std::uint32_t>(cores.size());
        const std::uint32_t w = config.core.warpWidth;
        const auto size = [&](std::uint32_t warp) {
            return std::min<std::uint32_t>(w, static_cast<std::uint32_t>(batch.rays.size()) - warp * w);
        };
        for (auto& core : cores) core->beginBatch(batch.rayTypes.size());
        batch.warpLocal.resize(warpCount);
        for (std::uint32_t warp = 0; warp < warpCount; ++warp) {
            const std::uint32_t k =
                config.gpu.dispatch == WarpDispatch::RoundRobin
                    ? warp % n
                    : static_cast<std::uint32_t>((std::uint64_t(warp) * n) / warpCount);  // contiguous runs
            batch.warpLocal[warp] = cores[k]->addWarp(warp, size(warp));
        }
    }

    // The host threads the process allows (TBB's arena and any global limit).
    static unsigned hostThreads() {
        const std::size_t arena = static_cast<std::size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
        const std::size_t limit = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
        return static_cast<unsigned>(std::max<std::size_t>(1, std::min(arena, limit)));
    }

    // Visits, in the serial model's order (cycle, then core index, then the
    // core's own order), the entries of per-core logs that are each sorted by
    // cycle: visitor(core, entry index). `cursor` is scratch, one per core.
    template <class CycleOf, class SizeOf, class Visitor>
    void mergeByCycle(std::vector<std::size_t>& cursor, const CycleOf& cycleOf, const SizeOf& sizeOf,
                      Visitor&& visitor) const {
        const std::size_t n = cores.size();
        cursor.assign(n, 0);
        for (;;) {
            std::size_t best = n;
            std::uint64_t bestCycle = ~std::uint64_t(0);
            for (std::size_t k = 0; k < n; ++k)
                if (cursor[k] < sizeOf(k) && (best == n || cycleOf(k, cursor[k]) < bestCycle)) {
                    best = k;
                    bestCycle = cycleOf(k, cursor[k]);
                }
            if (best == n) return;
            // This core's entries of that cycle, then the next core's.
            const std::size_t size = sizeOf(best);
            while (cursor[best] < size && cycleOf(best, cursor[best]) == bestCycle) visitor(best, cursor[best]++);
        }
    }

    // The cores in lock step until every ray of the batch is returned.
    //   parallel = false: one cycle at a time, cores in index order, L2
    //     reads answered at once (the serial model itself).
    //   parallel = true: host-parallel epochs. In l2 mode ideal the cores
    //     share nothing and each runs the whole batch on its own; in mode
    //     cache an epoch starting at E (the earliest next active cycle of any
    //     core) lasts minReadLatency cycles, shorter than the time from any L2
    //     read made in it to its answer. The cores run their cycles of the
    //     epoch on up to hostThreads() threads (core k on group k mod groups),
    //     their L2 reads logged; then the reads are answered serially in the
    //     serial model's order and every core takes its answers
    //     (resolveDeferred). Cycles and statistics are the serial model's,
    //     whatever the number of threads.
    void simulate(bool parallel) {
        constexpr std::uint64_t kNever = Core::kNever;
        const std::size_t n = cores.size();
        const bool deferring = parallel && l2;
        const std::uint64_t length =
            !parallel ? 1 : deferring ? cores[0]->port.minReadLatency(config.cache.lineBytes) : kNever;
        for (auto& core : cores) {
            core->visit = now;
            core->lastVisit = now;
            core->accountPending = false;
            core->deferring = deferring;
            core->port.defer(deferring ? &core->deferredReads : nullptr);
        }
        const std::size_t groups = parallel ? std::min<std::size_t>(hostThreads(), n) : 1;
        // One core's part of an epoch: first the answers of the previous
        // epoch's L2 reads, then its cycles of this one.
        const auto runCore = [&](Core& core, std::uint64_t end) {
            core.resolveDeferred();
            core.settle(everyCycle);
            core.runEpochCatching(end, everyCycle);
        };
        std::uint64_t epoch = now;
        for (;;) {
            clock = epoch;
            const std::uint64_t end = length == kNever ? kNever : epoch + length;
            if (!parallel) {
                for (auto& core : cores) core->runEpoch(end, everyCycle);  // throws through
            } else if (groups == 1) {
                for (auto& core : cores) runCore(*core, end);
            } else {
                parallelForEach(groups, [&](std::size_t g) {
                    for (std::size_t k = g; k < n; k += groups) runCore(*cores[k], end);
                });
            }
            if (deferring) answerL2Reads(groups);
            // The next epoch starts at the earliest cycle any core may act in:
            // its next active cycle so far, or the earliest answer to its reads
            // (a fetch waiting for one is done at or after it).
            epoch = kNever;
            bool allDone = true, failed = false;
            for (auto& core : cores) {
                epoch = std::min({epoch, core->visit, core->deferredReady});
                allDone = allDone && core->done();
                failed = failed || core->error;
            }
            if (failed || allDone) {
                for (auto& core : cores) core->resolveDeferred();  // placeholders out of the node caches
                if (failed) rethrowFirstError();
                break;
            }
            if (epoch == kNever) throw std::logic_error("rtcore_sim: no event pending while rays are in flight");
        }
        // The batch ends when its last result is returned.
        clock = now;
        for (auto& core : cores)
            if (core->rayCount > 0) clock = std::max(clock, core->lastVisit);
        for (auto& core : cores) core->port.defer(nullptr);
    }

    // Between epochs: the epoch's L2 reads of all cores, answered in the
    // serial model's order (each core takes its answers in its next task).
    // Reads of different line classes (SharedL2::classOf) touch disjoint
    // banks, sets and DRAM channels, so only the order within a class
    // matters: with several host threads, group g answers the classes c with
    // c mod groups = g, each in the serial order, with its own counters and
    // LRU stamps.
    void answerL2Reads(std::size_t threads) {
        const std::size_t n = cores.size();
        const std::size_t classes = l2->classes();
        for (auto& core : cores) core->deferredReads.fills.resize(core->deferredReads.reads.size());
        const std::size_t groups = std::max<std::size_t>(1, std::min(threads, classes));
        if (l2Groups.size() < groups) l2Groups.resize(groups);
        const auto answer = [&](std::size_t g) {
            L2Group& group = l2Groups[g];
            group.counters = L2Counters{};
            group.stamp = l2->stamp();
            group.ready.assign(n, Core::kNever);
            for (std::size_t c = g; c < classes; c += groups)
                mergeByCycle(
                    group.cursor,
                    [&](std::size_t k, std::size_t i) {
                        const DeferredReads& d = cores[k]->deferredReads;
                        return d.reads[d.byClass[c][i]].cycle;
                    },
                    [&](std::size_t k) { return cores[k]->deferredReads.byClass[c].size(); },
                    [&](std::size_t k, std::size_t i) {
                        DeferredReads& d = cores[k]->deferredReads;
                        const std::uint32_t index = d.byClass[c][i];
                        const DeferredReads::Read& r = d.reads[index];
                        const LineFill f =
                            cores[k]->port.atCore(l2->access(r.address, r.arrive, group.counters, group.stamp));
                        d.fills[index] = f;
                        group.ready[k] = std::min(group.ready[k], f.ready);
                    });
        };
        if (groups == 1) answer(0);
        else parallelForEach(groups, answer);
        std::uint64_t stamp = l2->stamp();
        for (std::size_t g = 0; g < groups; ++g) {
            const L2Group& group = l2Groups[g];
            l2->counters.add(group.counters);
            stamp = std::max(stamp, group.stamp);
            for (std::size_t k = 0; k < n; ++k) cores[k]->deferredReady = std::min(cores[k]->deferredReady, group.ready[k]);
        }
        l2->setStamp(stamp);
    }

    // A side callback threw in a host-parallel epoch: every core has run to the
    // epoch's end or to its own exception; the clock is the last cycle any core
    // reached, the exception rethrown the one the serial model would have met
    // first (smallest cycle, then core index).
    [[noreturn]] void rethrowFirstError() {
        Core* first = nullptr;
        clock = now;
        for (auto& core : cores) {
            clock = std::max(clock, core->lastVisit);
            if (core->error && (!first || core->errorCycle < first->errorCycle)) first = core.get();
        }
        std::rethrow_exception(first->error);
    }

    // The batch's per-core ray-type sums and activity, into the GPU's
    // RayTypeStats in the serial model's order (at the batch's end, or when
    // it is dropped).
    void mergeRayTypes() {
        for (auto& core : cores) {
            for (std::size_t t = 0; t < core->typeWork.size() && t < batch.rayTypes.size(); ++t) {
                RayTypeWork& w = core->typeWork[t];
                if (w.rays == 0 && w.nodeVisits == 0 && w.triangleTests == 0 && w.instanceTransitions == 0) continue;
                RayTypeStats& r = batch.rayTypes[t];
                r.rays += w.rays;
                r.latency.merge(w.latency);
                r.nodeVisits += w.nodeVisits;
                r.triangleTests += w.triangleTests;
                r.instanceTransitions += w.instanceTransitions;
                w = RayTypeWork{};
            }
        }
        mergeByCycle(cursor, [&](std::size_t k, std::size_t i) { return cores[k]->activity[i].cycle; },
                     [&](std::size_t k) { return cores[k]->activity.size(); },
                     [&](std::size_t k, std::size_t i) {
                         const Activity& a = cores[k]->activity[i];
                         RayTypeStats& r = batch.rayTypes[a.type];
                         if (a.delta > 0) {
                             if (r.inFlight == 0) r.activeSince = a.cycle;
                             r.inFlight += static_cast<std::uint64_t>(a.delta);
                         } else {
                             r.inFlight -= static_cast<std::uint64_t>(-std::int64_t(a.delta));
                             if (r.inFlight == 0) r.activeCycles += a.cycle - r.activeSince;
                         }
                     });
        for (auto& core : cores) core->activity.clear();
    }

    std::uint64_t portsFree(std::uint64_t c) const {
        for (const auto& core : cores) c = std::max(c, core->port.channel.nextFree());
        return c;
    }

    void run(std::span<const SimRay> rays, ProgrammableSide& programmable, std::span<SimRayResult> out) {
        if (rays.size() != out.size()) throw std::invalid_argument("RtCore::run: rays and results differ in size");
        if (rays.size() > UINT32_MAX / 2) throw std::invalid_argument("RtCore::run: batch too large");
        for (const SimRay& r : rays)
            if (r.rayType >= kMaxRayTypes)
                throw std::invalid_argument("RtCore::run: rayType " + std::to_string(r.rayType) + " >= " +
                                            std::to_string(kMaxRayTypes));
        if (scene.generation() != layoutGeneration) {
            if (layoutGeneration != ~std::uint64_t(0)) {
                for (auto& core : cores) core->cache.invalidate();
                if (l2) l2->invalidate();
            }
            layout.build(scene);
            layoutGeneration = scene.generation();
        }
        if (rays.empty()) return;
        // Step: the ray order before warp formation (gpu.rayOrder).
        batch.order.clear();
        if (config.gpu.rayOrder == RayOrder::DirectionOrigin) {
            batch.order = directionOriginOrder(rays);
            orderedRays.resize(rays.size());
            for (std::size_t i = 0; i < rays.size(); ++i) orderedRays[i] = rays[batch.order[i]];
            orderedResults.assign(rays.size(), SimRayResult{});
            rays = orderedRays;
        }
        batch.rays = rays;
        batch.side = &programmable;
        batch.results = batch.order.empty() ? out : std::span<SimRayResult>(orderedResults);
        const std::uint32_t w = config.core.warpWidth;
        const std::uint32_t warps = static_cast<std::uint32_t>((rays.size() + w - 1) / w);
        batch.warpSubmit.assign(warps, 0);
        std::uint32_t maxType = 0;
        for (const SimRay& r : rays) maxType = std::max(maxType, r.rayType);
        if (batch.rayTypes.size() <= maxType) batch.rayTypes.resize(maxType + 1);
        ++batches;
        dispatch(warps);

        try {
            // Host-parallel epochs when the side allows concurrent callbacks and
            // there are several cores; the number of host threads changes the
            // speed only.
            simulate(cores.size() > 1 && programmable.concurrent());
            now = portsFree(clock);  // spill writes drain before the batch ends
            mergeRayTypes();
            for (std::size_t i = 0; i < batch.order.size(); ++i) out[batch.order[i]] = orderedResults[i];
        } catch (...) {
            abortBatch();
            throw;
        }
        batch.rays = {};
        batch.results = {};
        batch.side = nullptr;
    }

    // A side callback threw: drop the batch's rays; the clock stays at the cycle reached.
    void abortBatch() {
        now = portsFree(clock);
        for (auto& core : cores) core->port.defer(nullptr);
        mergeRayTypes();
        for (auto& core : cores) core->abortBatch(now);
        for (RayTypeStats& t : batch.rayTypes) t.inFlight = 0;
        batch.rays = {};
        batch.results = {};
        batch.side = nullptr;
    }

    void resetStats() {
        const std::size_t types = batch.rayTypes.size();
        batch.rayTypes.assign(types, RayTypeStats{});
        frameStart = now;
        batches = 0;
        for (auto& core : cores) core->resetStats(now);
        if (l2) l2->resetStats();
    }

    void reset() {
        now = 0;
        for (auto& core : cores) core->resetTime();
        if (l2) {
            l2->invalidate();
            l2->resetTime();
        }
        resetStats();
    }

    nlohmann::json statsJson() const;
};

nlohmann::json RtCore::Impl::statsJson() const {
    using nlohmann::json;
    const std::uint64_t cycles = now - frameStart;
    const auto rate = [](double a, double b) { return b > 0.0 ? a / b : 0.0; };
    const std::uint32_t n = static_cast<std::uint32_t>(cores.size());

    std::vector<CoreSnapshot> snaps;
    for (const auto& core : cores) snaps.push_back(core->snapshot(now));
    CoreSnapshot all = snaps[0];
    for (std::uint32_t k = 1; k < n; ++k) all.merge(snaps[k]);

    json out = coreTreeJson(all, config, n, cycles, batches);
    out["config"] = config.toJson();

    json types = json::object();
    for (std::size_t t = 0; t < batch.rayTypes.size(); ++t) {
        const RayTypeStats& r = batch.rayTypes[t];
        if (r.rays == 0 && r.inFlight == 0) continue;
        json j;
        j["rays"] = r.rays;
        j["activeCycles"] = r.activeCycles + (r.inFlight ? now - r.activeSince : 0);
        j["latency"] = r.latency.toJson();
        j["nodeVisitsPerRay"] = rate(double(r.nodeVisits), double(r.rays));
        j["triangleTestsPerRay"] = rate(double(r.triangleTests), double(r.rays));
        j["instanceTransitionsPerRay"] = rate(double(r.instanceTransitions), double(r.rays));
        types[std::to_string(t)] = std::move(j);
    }
    out["rayTypes"] = std::move(types);

    out["gpu"] = {{"cores", n}, {"dispatch", toString(config.gpu.dispatch)}, {"rayOrder", toString(config.gpu.rayOrder)}};
    json perCore = json::array();
    for (std::uint32_t k = 0; k < n; ++k) perCore.push_back(coreTreeJson(snaps[k], config, 1, cycles, batches));
    out["cores"] = std::move(perCore);

    // The shared L2 and DRAM. Mode ideal: every L1 miss is an L2 hit with no bank and no DRAM.
    json l2j;
    l2j["mode"] = toString(config.l2.mode);
    json dram;
    dram["channels"] = config.dram.channels;
    dram["peakBytesPerCycle"] = std::uint64_t(config.dram.channels) * config.dram.bytesPerCycle;
    if (l2) {
        const std::uint64_t bankBusy = std::accumulate(l2->bankBusyCycles.begin(), l2->bankBusyCycles.end(), std::uint64_t(0));
        const std::uint64_t bankMax = *std::max_element(l2->bankBusyCycles.begin(), l2->bankBusyCycles.end());
        l2j["sizeBytes"] = config.l2.sizeBytes;
        l2j["banks"] = config.l2.banks;
        l2j["accesses"] = l2->counters.accesses;
        l2j["hits"] = l2->counters.hits;
        l2j["pendingHits"] = l2->counters.pendingHits;
        l2j["misses"] = l2->counters.misses;
        l2j["evictions"] = l2->counters.evictions;
        l2j["invalidations"] = l2->invalidations;
        l2j["hitRate"] = rate(double(l2->counters.hits), double(l2->counters.accesses));
        l2j["bankConflicts"] = l2->counters.bankConflicts;
        l2j["bankWaitCycles"] = l2->counters.bankWaitCycles;
        l2j["bankBusyCycles"] = bankBusy;
        l2j["busiestBankBusyCycles"] = bankMax;
        l2j["bankUtilization"] = rate(double(bankBusy), double(cycles) * config.l2.banks);
        l2j["busiestBankUtilization"] = rate(double(bankMax), double(cycles));
        const std::uint64_t chBusy =
            std::accumulate(l2->channelBusyCycles.begin(), l2->channelBusyCycles.end(), std::uint64_t(0));
        const std::uint64_t chMax = *std::max_element(l2->channelBusyCycles.begin(), l2->channelBusyCycles.end());
        dram["reads"] = l2->counters.dramReads;
        dram["readBytes"] = l2->counters.dramReadBytes;
        dram["busyCycles"] = chBusy;
        dram["busiestChannelBusyCycles"] = chMax;
        dram["queueCycles"] = l2->counters.dramQueueCycles;
        dram["utilization"] = rate(double(chBusy), double(cycles) * config.dram.channels);
        dram["bytesPerCycle"] = rate(double(l2->counters.dramReadBytes), double(cycles));
    } else {
        l2j["accesses"] = all.cacheMisses;
        l2j["hits"] = all.cacheMisses;
        l2j["misses"] = 0;
        l2j["hitRate"] = all.cacheMisses ? 1.0 : 0.0;
        l2j["bankConflicts"] = 0;
        l2j["bankWaitCycles"] = 0;
        for (const char* key : {"reads", "readBytes", "busyCycles", "queueCycles"}) dram[key] = 0;
        dram["utilization"] = 0.0;
        dram["bytesPerCycle"] = 0.0;
    }
    out["l2"] = std::move(l2j);
    out["dram"] = std::move(dram);
    return out;
}

// ---------------------------------------------------------------------------

namespace {

void checkBvhParams(const RtCoreConfig& config, const ModelScene& scene) {
    for (const auto& f : bvhParamTable().fields())
        if (f.read(config.bvh) != f.read(scene.params()))
            throw std::invalid_argument("RtCore: the ModelScene was built with bvh." + f.info.name + " = " +
                                        f.read(scene.params()).dump() + ", the configuration says " +
                                        f.read(config.bvh).dump() + " (build the scene with config.bvh)");
}

}  // namespace

RtCore::RtCore(const RtCoreConfig& config, const ModelScene& scene) {
    config.validate("RT-core configuration");
    checkBvhParams(config, scene);
    impl_ = std::make_unique<Impl>(config, scene);
}

RtCore::~RtCore() = default;

void RtCore::run(std::span<const SimRay> rays, ProgrammableSide& side, std::span<SimRayResult> results) {
    impl_->run(rays, side, results);
}

nlohmann::json RtCore::statsJson() const { return impl_->statsJson(); }
void RtCore::resetStats() { impl_->resetStats(); }
void RtCore::reset() { impl_->reset(); }
std::uint64_t RtCore::cycle() const { return impl_->now; }
void RtCore::simulateEveryCycle(bool on) { impl_->everyCycle = on; }
const RtCoreConfig& RtCore::config() const { return impl_->config; }

}  // namespace rtlab::rtcore_sim
