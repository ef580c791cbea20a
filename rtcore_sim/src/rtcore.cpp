// The event-driven timing model of the RT core (docs/rtcore-model.md,
// "Timing model"). Every simulated cycle runs five phases in this order:
//   1. events due this cycle (fetch done -> unit, stack traffic, step done)
//   2. completion: up to completionPerCycle results leave the completion
//      queue; blocked finished rays move into the freed entries
//   3. submission: the next warp enters the input queue if it fits whole
//   4. admission: up to admitPerCycle rays move from the input queue into
//      free ray slots (and are ready at once)
//   5. issue: the scheduler issues up to issueWidth ready rays' next steps
// Cycles in which none of phases 2-5 can do anything are skipped: the clock
// jumps to the next event.
#include <rtlab/core/error.hpp>
#include <rtlab/rtcore_sim/cache.hpp>
#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/rtcore_sim/scheduler.hpp>
#include <rtlab/rtcore_sim/stats.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <deque>
#include <stdexcept>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim {
namespace {

// ---------------------------------------------------------------------------
// Events: (slot, phase) in a timing wheel of kWheelSize cycles, farther ones
// in an overflow heap. Events of one cycle run in the order they were scheduled.

enum Phase : std::uint32_t { kFetchDone = 0, kStackTraffic = 1, kStepDone = 2 };
constexpr std::uint32_t makeEvent(std::uint32_t slot, Phase phase) { return slot << 2 | phase; }

class EventWheel {
public:
    static constexpr std::uint64_t kSize = 4096;

    EventWheel() : buckets_(kSize) {}

    void schedule(std::uint64_t cycle, std::uint32_t event) {
        if (cycle - base_ < kSize) [[likely]] {  // also false for cycle < base_ (wraps around)
            const std::size_t b = cycle & (kSize - 1);
            buckets_[b].push_back(event);
            bits_[b >> 6] |= std::uint64_t(1) << (b & 63);
            ++inWheel_;
        } else {
            scheduleFar(cycle, event);
        }
    }
    // The window moves to [cycle, cycle + kSize); overflow events now inside
    // it join their buckets in (cycle, scheduling) order, before any event
    // scheduled directly for those cycles.
    void advance(std::uint64_t cycle) {
        base_ = cycle;
        while (!overflow_.empty() && overflow_.front().cycle < base_ + kSize) {
            std::pop_heap(overflow_.begin(), overflow_.end(), Later{});
            const Far far = overflow_.back();
            overflow_.pop_back();
            schedule(far.cycle, far.event);
        }
    }
    std::vector<std::uint32_t>& bucket(std::uint64_t cycle) { return buckets_[cycle & (kSize - 1)]; }
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
    [[gnu::noinline]] void scheduleFar(std::uint64_t cycle, std::uint32_t event) {
        if (cycle < base_) throw std::logic_error("rtcore_sim: event scheduled in the past");
        overflow_.push_back(Far{cycle, seq_++, event});
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
        std::uint64_t cycle, seq;
        std::uint32_t event;
    };
    struct Later {
        bool operator()(const Far& a, const Far& b) const { return a.cycle != b.cycle ? a.cycle > b.cycle : a.seq > b.seq; }
    };
    std::vector<std::vector<std::uint32_t>> buckets_;
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

}  // namespace

// ---------------------------------------------------------------------------

struct RtCore::Impl {
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

    RtCoreConfig config;
    const ModelScene& scene;
    MemoryLayout layout;
    std::uint64_t layoutGeneration = ~std::uint64_t(0);
    NodeCache cache;
    MemoryChannel memory;
    UnitPool boxUnits, triangleUnits, transformUnits;
    std::unique_ptr<SchedulerPolicy> policy;
    bool policyUsesAddress = true;
    std::size_t readyCount = 0;  // rays held by the policy
    bool everyCycle = false;     // debug: visit every cycle instead of jumping to the next event
    EventWheel wheel;
    std::vector<Slot> slots;
    std::vector<std::uint32_t> freeSlots;  // LIFO
    std::deque<Delivery> completionQueue;
    std::deque<std::uint32_t> blockedFinishers;  // finished rays waiting for a completion-queue entry (slots)
    std::uint64_t now = 0;    // the clock between batches
    std::uint64_t clock = 0;  // the cycle being simulated during a batch
    std::uint64_t nextAge = 0;

    // The batch being simulated.
    std::span<const SimRay> rays;
    ProgrammableSide* side = nullptr;
    std::span<SimRayResult> results;
    std::uint32_t submitted = 0, admitted = 0, delivered = 0;
    std::vector<std::uint64_t> warpSubmit;
    std::vector<std::uint32_t> warpRemaining;

    // Statistics (raw; rates at dump time).
    struct Stats {
        std::uint64_t frameStart = 0, batches = 0, warps = 0, raysSubmitted = 0, raysCompleted = 0;
        Histogram latency{Histogram::Scheme::Log2};
        Histogram steps = workHistogram(), nodeVisits = workHistogram(), leafVisits = workHistogram(),
                  boxTests = workHistogram(), triangleTests = workHistogram(), proceduralTests = workHistogram(),
                  instanceTransitions = workHistogram(), maxStackDepth = workHistogram();
        // Ray latency breakdown (ray-cycles); the parts sum to the latencies.
        std::uint64_t inputQueue = 0, scheduler = 0, fetch = 0, boxUnitWait = 0, boxUnit = 0, triangleUnitWait = 0,
                      triangleUnit = 0, transformUnitWait = 0, transformUnit = 0, shader = 0, stackRefill = 0,
                      completionBlocked = 0, completionQueue = 0;
        std::uint64_t fetchBeyondHit = 0;  // part of fetch: cycles beyond the hit latency (misses, memory queueing)
        // Core-level blocked cycles.
        std::uint64_t inputQueueFull = 0, noFreeRaySlot = 0, completionQueueFull = 0;
        // Scheduler.
        std::uint64_t issued = 0, issueCycles = 0;
        // Work by unit.
        std::uint64_t nodes = 0, boxes = 0, leaves = 0, triangleTestCount = 0, proceduralTestCount = 0, transforms = 0,
                      fetches = 0, fetchBytes = 0;
        std::uint64_t anyHitCalls = 0, intersectionCalls = 0;
        // Stack.
        std::uint64_t pushes = 0, pops = 0, spilledEntries = 0, spillWrites = 0, refills = 0, refilledEntries = 0;
        // SIMD (lockstep warp) efficiency.
        std::uint64_t warpsCompleted = 0, warpSteps = 0, warpLanes = 0, raySteps = 0;
        Histogram activeRaysPerWarpStep{Histogram::Scheme::Linear, 65};
        std::vector<RayTypeStats> rayTypes;
    } stats;
    OccupancyTracker inputQueueOcc, slotOcc, readyOcc, completionOcc;

    Impl(const RtCoreConfig& cfg, const ModelScene& s)
        : config(cfg), scene(s), cache(cfg.cache), memory(cfg.memory),
          boxUnits(cfg.traversal.units, cfg.traversal.latency),
          triangleUnits(cfg.triangle.units, cfg.triangle.latency),
          transformUnits(cfg.transform.units, cfg.transform.latency), policy(makeSchedulerPolicy(cfg.scheduler)),
          slots(cfg.core.raySlots), inputQueueOcc(cfg.core.inputQueueRays), slotOcc(cfg.core.raySlots),
          readyOcc(cfg.core.raySlots), completionOcc(cfg.core.completionQueueRays) {
        policyUsesAddress = policy->usesAddress();
        resetSlots();
    }

    void resetSlots() {
        freeSlots.clear();
        for (std::uint32_t i = static_cast<std::uint32_t>(slots.size()); i-- > 0;) freeSlots.push_back(i);
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
        s.trav.step(*side, s.rayIndex, st);

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

        // Step: fetch the node, leaf or instance through the node cache.
        const MemoryRange range = stepRange(st);
        const std::uint64_t fetched = cache.fetch(range, c, memory);
        ++stats.fetches;
        stats.fetchBytes += range.bytes;
        stats.fetch += fetched - c;
        stats.fetchBeyondHit += fetched - c > config.cache.hitLatency ? fetched - c - config.cache.hitLatency : 0;
        wheel.schedule(fetched, makeEvent(slot, kFetchDone));
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
        // Spills are writes (they occupy the channel, nobody waits); the
        // step's refills are one read the ray waits for.
        if (s.spillEntries) {
            memory.write(c, s.spillEntries * config.stack.entryBytes);
            ++stats.spillWrites;
        }
        std::uint64_t r = c;
        if (s.refillEntries) r = memory.read(c, s.refillEntries * config.stack.entryBytes);
        stats.stackRefill += r - c;
        wheel.schedule(r, makeEvent(slot, kStepDone));
    }

    void finish(std::uint32_t slot, std::uint64_t c) {
        Slot& s = slots[slot];
        s.finishCycle = c;
        SimRayResult& r = results[s.rayIndex];
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
        RayTypeStats& type = stats.rayTypes[rays[s.rayIndex].rayType];
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
        const std::uint64_t latency = c - warpSubmit[warp];
        stats.completionQueue += c - d.enterCycle;
        results[d.rayIndex].cycles = static_cast<std::uint32_t>(std::min<std::uint64_t>(latency, UINT32_MAX));
        stats.latency.add(latency);
        ++stats.raysCompleted;
        RayTypeStats& type = stats.rayTypes[rays[d.rayIndex].rayType];
        ++type.rays;
        type.latency.add(latency);
        if (--type.inFlight == 0) type.activeCycles += c - type.activeSince;
        ++delivered;
        if (--warpRemaining[warp] == 0) warpDone(warp);
    }

    // SIMD efficiency of a lockstep traversal of this warp: warp step k has
    // the rays with more than k steps active.
    void warpDone(std::uint32_t warp) {
        const std::uint32_t width = config.core.warpWidth;
        const std::uint32_t first = warp * width;
        const std::uint32_t last = std::min<std::uint32_t>(first + width, static_cast<std::uint32_t>(rays.size()));
        std::array<std::uint32_t, 64> steps;
        const std::uint32_t m = last - first;
        for (std::uint32_t i = 0; i < m; ++i) steps[i] = results[first + i].work.steps;
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

    // ---- the cycle loop ----------------------------------------------------

    void processEvents(std::uint64_t c) {
        std::vector<std::uint32_t>& bucket = wheel.bucket(c);
        for (std::size_t i = 0; i < bucket.size(); ++i) {  // handlers may append events for this cycle
            const std::uint32_t event = bucket[i];
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
        return std::min<std::uint32_t>(config.core.warpWidth, static_cast<std::uint32_t>(rays.size()) - submitted);
    }
    bool pendingWarpFits() const {
        return submitted < rays.size() && config.core.inputQueueRays - (submitted - admitted) >= pendingWarpSize();
    }

    void submission(std::uint64_t c) {
        if (submitted == rays.size()) return;
        if (!pendingWarpFits()) {
            ++stats.inputQueueFull;
            return;
        }
        const std::uint32_t size = pendingWarpSize();
        warpSubmit[submitted / config.core.warpWidth] = c;
        for (std::uint32_t i = submitted; i < submitted + size; ++i) {
            RayTypeStats& type = stats.rayTypes[rays[i].rayType];
            if (type.inFlight++ == 0) type.activeSince = c;
        }
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
            s.rayIndex = admitted++;
            s.warp = s.rayIndex / config.core.warpWidth;
            s.age = nextAge++;
            s.admitCycle = c;
            s.onChip = s.spilled = s.spills = s.refills = 0;
            s.trav.begin(scene, rays[s.rayIndex]);
            stats.inputQueue += c - warpSubmit[s.warp];
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
    }

    void run(std::span<const SimRay> batch, ProgrammableSide& programmable, std::span<SimRayResult> out) {
        if (batch.size() != out.size()) throw std::invalid_argument("RtCore::run: rays and results differ in size");
        if (batch.size() > UINT32_MAX / 2) throw std::invalid_argument("RtCore::run: batch too large");
        for (const SimRay& r : batch)
            if (r.rayType >= kMaxRayTypes)
                throw std::invalid_argument("RtCore::run: rayType " + std::to_string(r.rayType) + " >= " +
                                            std::to_string(kMaxRayTypes));
        if (scene.generation() != layoutGeneration) {
            if (layoutGeneration != ~std::uint64_t(0)) cache.invalidate();
            layout.build(scene);
            layoutGeneration = scene.generation();
        }
        if (batch.empty()) return;
        rays = batch;
        side = &programmable;
        results = out;
        submitted = admitted = delivered = 0;
        const std::uint32_t warps = static_cast<std::uint32_t>((batch.size() + config.core.warpWidth - 1) / config.core.warpWidth);
        warpSubmit.assign(warps, 0);
        warpRemaining.assign(warps, config.core.warpWidth);
        warpRemaining.back() = static_cast<std::uint32_t>(batch.size()) - (warps - 1) * config.core.warpWidth;
        std::uint32_t maxType = 0;
        for (const SimRay& r : batch) maxType = std::max(maxType, r.rayType);
        if (stats.rayTypes.size() <= maxType) stats.rayTypes.resize(maxType + 1);
        ++stats.batches;

        try {
            std::uint64_t& c = clock;
            c = now;
            wheel.advance(c);
            for (;;) {
                processEvents(c);
                completion(c);
                submission(c);
                admission(c);
                issueRays(c);
                if (delivered == rays.size()) break;
                // Step: the next cycle with something to do.
                const bool busy = readyCount > 0 || !completionQueue.empty() ||
                                  (admitted < submitted && !freeSlots.empty()) || pendingWarpFits();
                std::uint64_t next = c + 1;
                if (!busy && !everyCycle && !wheel.nextAfter(c, next))
                    throw std::logic_error("rtcore_sim: no event pending while rays are in flight");
                if (everyCycle && !busy && wheel.empty())
                    throw std::logic_error("rtcore_sim: no event pending while rays are in flight");
                // Step: conditions that hold through the skipped cycles.
                if (submitted < rays.size() && !pendingWarpFits()) stats.inputQueueFull += next - c - 1;
                if (admitted < submitted && freeSlots.empty()) stats.noFreeRaySlot += next - c;
                if (!blockedFinishers.empty()) stats.completionQueueFull += next - c;
                c = next;
                wheel.advance(c);
            }
            now = std::max(c, memory.nextFree());  // spill writes drain before the batch ends
        } catch (...) {
            abortBatch();
            throw;
        }
        rays = {};
        results = {};
        side = nullptr;
    }

    // A side callback threw: drop the batch's rays; the clock stays at the cycle reached.
    void abortBatch() {
        now = std::max(clock, memory.nextFree());
        wheel.clear();
        policy = makeSchedulerPolicy(config.scheduler);
        readyCount = 0;
        completionQueue.clear();
        blockedFinishers.clear();
        resetSlots();
        for (RayTypeStats& t : stats.rayTypes) t.inFlight = 0;
        inputQueueOcc.set(0, now);
        slotOcc.set(0, now);
        readyOcc.set(0, now);
        completionOcc.set(0, now);
        rays = {};
        results = {};
        side = nullptr;
    }

    void resetStats() {
        const std::size_t types = stats.rayTypes.size();
        stats = Stats{};
        stats.rayTypes.resize(types);
        stats.frameStart = now;
        boxUnits.resetStats();
        triangleUnits.resetStats();
        transformUnits.resetStats();
        cache.resetStats();
        cache.invalidations = 0;
        memory.resetStats();
        policy->resetStats();
        inputQueueOcc.reset(now);
        slotOcc.reset(now);
        readyOcc.reset(now);
        completionOcc.reset(now);
    }

    nlohmann::json statsJson() const;
};

// ---------------------------------------------------------------------------
// The stats tree.

nlohmann::json RtCore::Impl::statsJson() const {
    using nlohmann::json;
    const std::uint64_t cycles = now - stats.frameStart;
    const auto rate = [](double a, double b) { return b > 0.0 ? a / b : 0.0; };
    const auto unitJson = [&](const UnitPool& u, std::uint32_t count) {
        json j;
        j["units"] = count;
        j["requests"] = u.requests;
        j["busyCycles"] = u.busyCycles;
        j["waitCycles"] = u.waitCycles;
        j["utilization"] = rate(double(u.busyCycles), double(cycles) * count);
        return j;
    };

    json out;
    out["config"] = config.toJson();
    out["frame"] = {{"cycles", cycles},
                    {"batches", stats.batches},
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

    json types = json::object();
    for (std::size_t t = 0; t < stats.rayTypes.size(); ++t) {
        const RayTypeStats& r = stats.rayTypes[t];
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

    out["submission"] = {{"warpWidth", config.core.warpWidth},
                         {"warps", stats.warps},
                         {"blockedCycles", {{"inputQueueFull", stats.inputQueueFull}}},
                         {"inputQueue",
                          {{"capacity", config.core.inputQueueRays}, {"occupancy", inputQueueOcc.toJson(now)}}}};
    out["raySlots"] = {{"count", slots.size()},
                       {"occupancy", slotOcc.toJson(now)},
                       {"utilization", rate(slotOcc.toJson(now)["mean"].get<double>(), double(slots.size()))},
                       {"blockedCycles", {{"noFreeRaySlot", stats.noFreeRaySlot}}}};

    json sched;
    sched["policy"] = config.scheduler.policy;
    sched["issueWidth"] = config.scheduler.issueWidth;
    sched["issued"] = stats.issued;
    sched["issueCycles"] = stats.issueCycles;
    sched["utilization"] = rate(double(stats.issued), double(cycles) * config.scheduler.issueWidth);
    sched["readyRays"] = readyOcc.toJson(now);
    sched["waitCycles"] = stats.scheduler;
    policy->addStats(sched);
    out["scheduler"] = std::move(sched);

    json traversal = unitJson(boxUnits, config.traversal.units);
    traversal["nodes"] = stats.nodes;
    traversal["boxTests"] = stats.boxes;
    out["traversalUnits"] = std::move(traversal);
    json triangle = unitJson(triangleUnits, config.triangle.units);
    triangle["leaves"] = stats.leaves;
    triangle["triangleTests"] = stats.triangleTestCount;
    triangle["proceduralTests"] = stats.proceduralTestCount;
    out["triangleUnits"] = std::move(triangle);
    json transform = unitJson(transformUnits, config.transform.units);
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
                    {"accesses", cache.accesses},
                    {"hits", cache.hits},
                    {"pendingHits", cache.pendingHits},
                    {"misses", cache.misses},
                    {"evictions", cache.evictions},
                    {"invalidations", cache.invalidations},
                    {"hitRate", rate(double(cache.hits), double(cache.accesses))}};
    out["memory"] = {{"reads", memory.reads},
                     {"readBytes", memory.readBytes},
                     {"writes", memory.writes},
                     {"writeBytes", memory.writeBytes},
                     {"busyCycles", memory.busyCycles},
                     {"queueCycles", memory.queueCycles},
                     {"utilization", rate(double(memory.busyCycles), double(cycles))},
                     {"bytesPerCycle", rate(double(memory.readBytes + memory.writeBytes), double(cycles))}};
    out["completion"] = {{"capacity", config.core.completionQueueRays},
                         {"occupancy", completionOcc.toJson(now)},
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

void RtCore::reset() {
    impl_->now = 0;
    impl_->nextAge = 0;
    impl_->wheel.clear();
    impl_->wheel.advance(0);
    impl_->cache.invalidate();
    impl_->memory.resetTime();
    impl_->boxUnits.resetTime();
    impl_->triangleUnits.resetTime();
    impl_->transformUnits.resetTime();
    impl_->resetStats();
}

std::uint64_t RtCore::cycle() const { return impl_->now; }
void RtCore::simulateEveryCycle(bool on) { impl_->everyCycle = on; }
const RtCoreConfig& RtCore::config() const { return impl_->config; }

}  // namespace rtlab::rtcore_sim
