// One RT core's share of the timing model: a ray's life (issue, fetch, units, shader round trips, short
// stack, completion), the five phases of a cycle, and the core's side of the GPU loop (runEpoch, settle).
#include "core_cycle.hpp"

#include <algorithm>
#include <array>
#include <cstdint>

namespace rtlab::rtcore_sim {
namespace {

std::uint32_t ceilDiv(std::uint32_t a, std::uint32_t b) { return (a + b - 1) / b; }

}  // namespace

Core::Core(const RtCoreConfig& cfg, const ModelScene& s, const MemoryLayout& l, BatchState& b, SharedL2* l2)
    : config(cfg), scene(s), layout(l), batch(b), cache(cfg.cache), port(cfg.memory, l2, cfg.l2.hitLatency),
      boxUnits(cfg.traversal.units, cfg.traversal.latency), triangleUnits(cfg.triangle.units, cfg.triangle.latency),
      transformUnits(cfg.transform.units, cfg.transform.latency), policy(makeSchedulerPolicy(cfg.scheduler)),
      slots(cfg.core.raySlots), inputQueueOcc(cfg.core.inputQueueRays), slotOcc(cfg.core.raySlots),
      readyOcc(cfg.core.raySlots), completionOcc(cfg.core.completionQueueRays) {
    policyUsesAddress = policy->usesAddress();
    policyPrefetches = !isBuiltinNonPrefetching(cfg.scheduler.policy);  // saves a virtual call per cycle
    resetSlots();
}

inline bool Core::isBuiltinNonPrefetching(const std::string& name) {
    return name == "fifo" || name == "oldestFirst" || name == "treelet";
}

inline void Core::resetSlots() {
    freeSlots.clear();
    for (std::uint32_t i = static_cast<std::uint32_t>(slots.size()); i-- > 0;) freeSlots.push_back(i);
}

// The batch index of the k-th ray of this core's sequence.
inline std::uint32_t Core::rayAt(std::uint32_t k) const { return sequence[k]; }

// ---- addresses ----------------------------------------------------------

inline MemoryRange Core::stepRange(const StepInfo& st) const {
    switch (st.kind) {
        case StepKind::Instance: return layout.instance(st.index);
        case StepKind::TlasLeaf: return layout.tlasLeaf(scene.tlas().leaves[st.index], st.index);
        case StepKind::BlasLeaf: return layout.blasLeaf(st.mesh, scene.blas(st.mesh)->bvh.leaves[st.index], st.index);
        case StepKind::Node: return st.tlas ? layout.tlasNode(st.index) : layout.blasNode(st.mesh, st.index);
    }
    return {};
}
inline std::uint64_t Core::nextAddress(const Slot& s) const {
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

inline void Core::makeReady(std::uint32_t slot, std::uint64_t c) {
    Slot& s = slots[slot];
    s.readyCycle = c;
    if (s.trav.finished()) return finish(slot, c);
    policy->push(ReadyRay{slot, s.age, policyUsesAddress ? nextAddress(s) : 0});
    readyOcc.set(++readyCount, c);
}

inline void Core::issue(std::uint32_t slot, std::uint64_t c) {
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
        deferredFetches.push_back(DeferredFetch{events.reserve(), c, slot,
                                                static_cast<std::uint32_t>(fetched.ready & kDeferredIndex),
                                                static_cast<std::uint32_t>(fetched.l2Cycles)});
        return;
    }
    fetchTimed(fetched, c);
    events.schedule(fetched.ready, makeEvent(slot, kFetchDone));
}

// The latency breakdown's terms of a fetch issued at c.
inline void Core::fetchTimed(const LineFill& fetched, std::uint64_t c) {
    const std::uint64_t waited = fetched.ready - c;
    stats.fetch += waited - fetched.l2Cycles - fetched.dramCycles;
    stats.l2 += fetched.l2Cycles;
    stats.dram += fetched.dramCycles;
    stats.fetchBeyondHit += waited > config.cache.hitLatency ? waited - config.cache.hitLatency : 0;
}

// Between epochs, the epoch's L2 reads answered (deferredReads.fills):
// the node cache gets the fill cycles, each waiting fetch its time,
// statistics and fetch-done event.
void Core::resolveDeferred() {
    if (deferredReads.empty()) return;
    cache.resolve(deferredReads);
    for (const DeferredFetch& f : deferredFetches) {
        const LineFill fetched =
            cache.evaluate(f.cycle, deferredReads.terms.data() + f.firstTerm, f.terms, deferredReads);
        fetchTimed(fetched, f.cycle);
        events.scheduleAt(fetched.ready, makeEvent(f.slot, kFetchDone), f.seq);
    }
    deferredFetches.clear();
    deferredReads.clear();
    deferredReady = kNever;
}

inline void Core::onFetchDone(std::uint32_t slot, std::uint64_t c) {
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
    events.schedule(t, makeEvent(slot, s.spillEntries || s.refillEntries ? kStackTraffic : kStepDone));
}

inline void Core::onStackTraffic(std::uint32_t slot, std::uint64_t c) {
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
    events.schedule(r, makeEvent(slot, kStepDone));
}

inline void Core::finish(std::uint32_t slot, std::uint64_t c) {
    Slot& s = slots[slot];
    s.finishCycle = c;
    const TraversalCounters& w = s.trav.counters();
    batch.raySteps[s.rayIndex] = w.steps;
    if (!batch.results.empty()) {
        SimRayResult& r = batch.result(s.rayIndex);
        r.hit = s.trav.hit();
        r.work = w;
        r.stackSpills = s.spills;
        r.stackRefills = s.refills;
        r.slotCycles = static_cast<std::uint32_t>(std::min<std::uint64_t>(c - s.admitCycle, UINT32_MAX));
    }
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
    RayTypeWork& type = typeWork[batch.ray(s.rayIndex).rayType];
    type.nodeVisits += w.nodeVisits;
    type.triangleTests += w.triangleTests;
    type.instanceTransitions += w.instanceTransitions;
    if (completionQueue.size() < config.core.completionQueueRays) enterCompletion(slot, c);
    else blockedFinishers.push_back(slot);
}

inline void Core::enterCompletion(std::uint32_t slot, std::uint64_t c) {
    Slot& s = slots[slot];
    stats.completionBlocked += c - s.finishCycle;
    completionQueue.push_back(Delivery{s.rayIndex, s.group, c});
    completionOcc.set(completionQueue.size(), c);
    freeSlots.push_back(slot);
    slotOcc.set(slots.size() - freeSlots.size(), c);
}

inline void Core::deliver(const Delivery& d, std::uint64_t c) {
    const std::uint64_t latency = c - batch.groupSubmit[d.group];
    stats.completionQueue += c - d.enterCycle;
    if (!batch.results.empty())
        batch.result(d.rayIndex).cycles = static_cast<std::uint32_t>(std::min<std::uint64_t>(latency, UINT32_MAX));
    stats.latency.add(latency);
    ++stats.raysCompleted;
    const std::uint32_t rayType = batch.ray(d.rayIndex).rayType;
    RayTypeWork& type = typeWork[rayType];
    ++type.rays;
    type.latency.add(latency);
    logActivity(c, rayType, -1);
    ++delivered;
    if (--batch.groupRemaining[d.group] == 0) groupDone(d.group, c);
}

inline void Core::logActivity(std::uint64_t c, std::uint32_t rayType, std::int32_t delta) {
    if (!activity.empty()) {
        Activity& last = activity.back();
        if (last.cycle == c && last.type == rayType && (last.delta > 0) == (delta > 0)) {
            last.delta += delta;
            return;
        }
    }
    activity.push_back(Activity{c, rayType, delta});
}

// A group's last result is back. SIMD efficiency of a lockstep traversal of
// the group: warp step k has the rays with more than k steps active. Then
// the warp's next group is ready after the shader latency, or, when it has
// none, the warp leaves and the core's next warp becomes resident.
inline void Core::groupDone(std::uint32_t group, std::uint64_t c) {
    const std::uint32_t width = config.core.warpWidth;
    const std::uint32_t first = batch.groupFirst[group];
    std::array<std::uint32_t, 64> steps;
    const std::uint32_t m = batch.groupSize[group];
    for (std::uint32_t i = 0; i < m; ++i) steps[i] = batch.raySteps[first + i];
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

    const std::uint32_t warp = batch.groupWarp[group];
    const std::uint32_t slot = residentOfWarp[batch.warpLocal[warp]];
    if (group + 1 < batch.warpGroups[warp + 1]) {
        resident[slot].group = group + 1;
        if (batch.nextTraceLatency == 0) readyGroups.push_back(group + 1);
        else events.schedule(c + batch.nextTraceLatency, makeEvent(slot, kGroupReady));
        return;
    }
    freeResident.push_back(slot);
    becomeResident();
}

// The core's next warp takes a free residency slot; its first group is ready at once.
inline void Core::becomeResident() {
    if (nextWarp == warps.size() || freeResident.empty()) return;
    const std::uint32_t slot = freeResident.back();
    freeResident.pop_back();
    const std::uint32_t warp = warps[nextWarp];
    residentOfWarp[nextWarp++] = slot;
    resident[slot] = Resident{warp, batch.warpGroups[warp]};
    readyGroups.push_back(resident[slot].group);
}

// ---- one cycle -----------------------------------------------------------

inline void Core::processEvents(std::uint64_t c) {
    std::uint32_t event, next;
    while (events.popDue(c, event)) {  // handlers may schedule events for this cycle: they follow
        const std::uint32_t slot = event >> 2;
        // The next event's ray slot on its way into the host's cache while
        // this one runs (the slots of 30 cores do not stay cached).
        if (events.peek(next) && (next & 3) != kGroupReady) {
            const char* line = reinterpret_cast<const char*>(&slots[next >> 2]);
            __builtin_prefetch(line);
            __builtin_prefetch(line + 64);
            __builtin_prefetch(slots[next >> 2].trav.nextEntryAddress());
        }
        switch (static_cast<Phase>(event & 3)) {
            case kFetchDone: onFetchDone(slot, c); break;
            case kStackTraffic: onStackTraffic(slot, c); break;
            case kStepDone: makeReady(slot, c); break;
            case kGroupReady: readyGroups.push_back(resident[slot].group); break;
        }
    }
}

inline void Core::completion(std::uint64_t c) {
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

inline std::uint32_t Core::pendingWarpSize() const { return batch.groupSize[readyGroups.front()]; }
inline bool Core::pendingWarpFits() const {
    return !readyGroups.empty() && config.core.inputQueueRays - (submitted() - admitted) >= pendingWarpSize();
}

inline void Core::submission(std::uint64_t c) {
    if (readyGroups.empty()) return;
    if (!pendingWarpFits()) {
        ++stats.inputQueueFull;
        return;
    }
    const std::uint32_t group = readyGroups.front();
    readyGroups.pop_front();
    const std::uint32_t first = batch.groupFirst[group], size = batch.groupSize[group];
    batch.groupSubmit[group] = c;
    for (std::uint32_t i = first; i < first + size; ++i) {
        logActivity(c, batch.ray(i).rayType, +1);
        sequence.push_back(i);
    }
    if (batch.reorderInput) {
        // The input queue's rays in key order (ties: launch order): the next admitted is the smallest key waiting.
        const auto& key = batch.rayKey;
        std::sort(sequence.begin() + admitted, sequence.end(),
                  [&key](std::uint32_t a, std::uint32_t b) { return key[a] != key[b] ? key[a] < key[b] : a < b; });
    }
    ++stats.warps;
    stats.raysSubmitted += size;
    inputQueueOcc.set(submitted() - admitted, c);
}

inline void Core::admission(std::uint64_t c) {
    for (std::uint32_t k = 0; k < config.core.admitPerCycle && admitted < submitted() && !freeSlots.empty(); ++k) {
        const std::uint32_t slot = freeSlots.back();
        freeSlots.pop_back();
        Slot& s = slots[slot];
        s.rayIndex = rayAt(admitted++);
        s.group = batch.rayGroup[s.rayIndex];
        s.age = nextAge++;
        s.admitCycle = c;
        s.onChip = s.spilled = s.spills = s.refills = 0;
        s.trav.begin(scene, batch.ray(s.rayIndex));
        stats.inputQueue += c - batch.groupSubmit[s.group];
        slotOcc.set(slots.size() - freeSlots.size(), c);
        makeReady(slot, c);
    }
    inputQueueOcc.set(submitted() - admitted, c);
}

inline void Core::issueRays(std::uint64_t c) {
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
inline void Core::cycle(std::uint64_t c) {
    processEvents(c);
    completion(c);
    submission(c);
    admission(c);
    issueRays(c);
}
// Whether one of phases 2-5 can act in the next cycle.
inline bool Core::busy() const {
    return readyCount > 0 || !completionQueue.empty() || (admitted < submitted() && !freeSlots.empty()) ||
           pendingWarpFits();
}
// Conditions that hold through the cycles after c up to next (exclusive), skipped or not.
inline void Core::accountUntil(std::uint64_t c, std::uint64_t next) {
    if (!readyGroups.empty() && !pendingWarpFits()) stats.inputQueueFull += next - c - 1;
    if (admitted < submitted() && freeSlots.empty()) stats.noFreeRaySlot += next - c;
    if (!blockedFinishers.empty()) stats.completionQueueFull += next - c;
}

void Core::beginBatch(std::size_t rayTypes) {
    warps.clear();
    nextWarp = 0;
    resident.clear();
    freeResident.clear();
    residentOfWarp.clear();
    readyGroups.clear();
    sequence.clear();
    rayCount = admitted = delivered = 0;
    if (typeWork.size() < rayTypes) typeWork.resize(rayTypes);
    activity.clear();
    deferredReads.clear();
    deferredFetches.clear();
    deferredReady = kNever;
    error = nullptr;
}
void Core::addWarp(std::uint32_t warp) {
    batch.warpLocal[warp] = static_cast<std::uint32_t>(warps.size());
    warps.push_back(warp);
    for (std::uint32_t g = batch.warpGroups[warp]; g < batch.warpGroups[warp + 1]; ++g) rayCount += batch.groupSize[g];
}
void Core::start() {
    const std::size_t slotsNow = std::min<std::size_t>(batch.residentWarps, warps.size());
    resident.assign(slotsNow, Resident{});
    residentOfWarp.assign(warps.size(), 0);
    sequence.reserve(rayCount);
    for (std::size_t i = slotsNow; i-- > 0;) freeResident.push_back(static_cast<std::uint32_t>(i));
    while (!freeResident.empty() && nextWarp < warps.size()) becomeResident();
}

// ---- the GPU loop --------------------------------------------------------

// Simulates this core's active cycles before `end` (from `visit`). It
// stops for good once all its rays are returned (nothing is left to
// happen). The accounting of skipped cycles up to the next active cycle
// is done here when that cycle is before `end`, otherwise left to
// settle() (a deferred fetch may make it earlier).
void Core::runEpoch(std::uint64_t end, bool everyCycle) {
    while (visit < end) {
        const std::uint64_t c = visit;
        events.advance(c);
        cycle(c);
        lastVisit = c;
        if (done()) {
            visit = kNever;
            return;
        }
        std::uint64_t n = c + 1;
        if (!busy() && !everyCycle && !events.nextAfter(c, n)) n = kNever;
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
void Core::runEpochCatching(std::uint64_t end, bool everyCycle) {
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
void Core::settle(bool everyCycle) {
    if (!accountPending) return;
    accountPending = false;
    const std::uint64_t c = lastVisit;
    std::uint64_t n = c + 1;
    if (!busy() && !everyCycle && !events.nextAfter(c, n)) n = kNever;
    if (n != kNever) accountUntil(c, n);
    visit = n;
}

// A side callback threw: drop the batch's rays.
void Core::abortBatch(std::uint64_t now) {
    deferredFetches.clear();
    deferredReads.clear();
    deferredReady = kNever;
    events.clear();
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

void Core::resetStats(std::uint64_t now) {
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

void Core::resetTime() {
    nextAge = 0;
    deferredFetches.clear();
    deferredReads.clear();
    deferredReady = kNever;
    events.clear();
    events.advance(0);
    cache.invalidate();
    port.channel.resetTime();
    boxUnits.resetTime();
    triangleUnits.resetTime();
    transformUnits.resetTime();
}

CoreSnapshot Core::snapshot(std::uint64_t now) const {
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

}  // namespace rtlab::rtcore_sim
