// The GPU level of the timing model (RtCore::Impl): a batch cut into warps and dispatched to the cores, the cores
// run in lock step or in host-parallel epochs, the epochs' L2 reads answered in the serial order, ray-type merges.
#include "gpu_level.hpp"

#include "ray_order.hpp"

#include <rtlab/core/parallel.hpp>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <exception>
#include <stdexcept>
#include <string>
#include <utility>

namespace rtlab::rtcore_sim {

RtCore::Impl::Impl(const RtCoreConfig& cfg, const ModelScene& s) : config(cfg), scene(s) {
    if (config.l2.mode == L2Mode::Cache) l2 = std::make_unique<SharedL2>(config.l2, config.dram);
    for (std::uint32_t k = 0; k < config.gpu.cores; ++k)
        cores.push_back(std::make_unique<Core>(config, scene, layout, batch, l2.get()));
}

// The dispatch rule: which core each warp goes to. Warps without rays
// (a launch's threads that traced nothing) go nowhere.
void RtCore::Impl::dispatch(std::uint32_t warpCount) {
    const std::uint32_t n = static_cast<std::uint32_t>(cores.size());
    for (auto& core : cores) core->beginBatch(batch.rayTypes.size());
    batch.warpLocal.assign(warpCount, 0);
    for (std::uint32_t warp = 0; warp < warpCount; ++warp) {
        if (batch.warpGroups[warp] == batch.warpGroups[warp + 1]) continue;
        const std::uint32_t k =
            config.gpu.dispatch == WarpDispatch::RoundRobin
                ? warp % n
                : static_cast<std::uint32_t>((std::uint64_t(warp) * n) / warpCount);  // contiguous runs
        cores[k]->addWarp(warp);
    }
    for (auto& core : cores) core->start();
}

// A tile batch: warp w = rays [w * warpWidth, ...) is one group.
void RtCore::Impl::tileGroups(std::uint32_t warps) {
    const std::uint32_t w = config.core.warpWidth;
    const auto n = static_cast<std::uint32_t>(batch.rays.size());
    batch.groupFirst.resize(warps);
    batch.groupSize.resize(warps);
    batch.groupWarp.resize(warps);
    batch.warpGroups.resize(warps + 1);
    batch.rayGroup.resize(n);
    for (std::uint32_t g = 0; g < warps; ++g) {
        batch.groupFirst[g] = g * w;
        batch.groupSize[g] = std::min(w, n - g * w);
        batch.groupWarp[g] = g;
        batch.warpGroups[g] = g;
        for (std::uint32_t i = g * w; i < g * w + batch.groupSize[g]; ++i) batch.rayGroup[i] = g;
    }
    batch.warpGroups[warps] = warps;
    batch.residentWarps = ~0u;
    batch.nextTraceLatency = 0;
    batch.reorderInput = false;
}

// The host threads the process allows (TBB's arena and any global limit).
unsigned RtCore::Impl::hostThreads() {
    const std::size_t arena = static_cast<std::size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
    const std::size_t limit = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
    return static_cast<unsigned>(std::max<std::size_t>(1, std::min(arena, limit)));
}

// Visits, in the serial model's order (cycle, then core index, then the
// core's own order), the entries of per-core logs that are each sorted by
// cycle: visitor(core, entry index). `cursor` is scratch, one per core.
template <class CycleOf, class SizeOf, class Visitor>
void RtCore::Impl::mergeByCycle(std::vector<std::size_t>& cursor, const CycleOf& cycleOf, const SizeOf& sizeOf,
                                Visitor&& visitor) const {
    const std::size_t n = cores.size();
    cursor.assign(n, 0);
    // The cores with entries left, in a min-heap on (next entry's cycle, core).
    using Head = std::pair<std::uint64_t, std::size_t>;
    std::vector<Head> heads;
    for (std::size_t k = 0; k < n; ++k)
        if (sizeOf(k) > 0) heads.emplace_back(cycleOf(k, 0), k);
    const auto later = [](const Head& a, const Head& b) { return a > b; };
    std::make_heap(heads.begin(), heads.end(), later);
    while (!heads.empty()) {
        std::pop_heap(heads.begin(), heads.end(), later);
        const auto [cycle, best] = heads.back();
        heads.pop_back();
        // This core's entries of that cycle, then the next core's.
        const std::size_t size = sizeOf(best);
        while (cursor[best] < size && cycleOf(best, cursor[best]) == cycle) visitor(best, cursor[best]++);
        if (cursor[best] < size) {
            heads.emplace_back(cycleOf(best, cursor[best]), best);
            std::push_heap(heads.begin(), heads.end(), later);
        }
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
void RtCore::Impl::simulate(bool parallel) {
    constexpr std::uint64_t kNever = Core::kNever;
    const std::size_t n = cores.size();
    const bool deferring = parallel && l2;
    const std::uint64_t length = !parallel   ? 1
                                 : deferring ? cores[0]->port.minReadLatency(config.cache.fillBytes())
                                             : kNever;
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
            // One task per core (the cores of an epoch share nothing): the
            // host threads take them as they come, so unequal cores balance,
            // each core preferably on the thread that ran it last.
            parallelForEach(
                n, [&](std::size_t k) { runCore(*cores[k], end); }, coreAffinity);
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
void RtCore::Impl::answerL2Reads(std::size_t threads) {
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
        for (std::size_t c = g; c < classes; c += groups) {
            // The serial model's order: by cycle, then core, then the core's
            // own order (each core's reads of a class are in cycle order) —
            // sorted once rather than merged with a scan over every core per read.
            group.order.clear();
            for (std::size_t k = 0; k < n; ++k) {
                const DeferredReads& d = cores[k]->deferredReads;
                const std::vector<std::uint32_t>& mine = d.byClass[c];
                for (std::uint32_t i = 0; i < mine.size(); ++i)
                    group.order.push_back(L2Group::Key{d.reads[mine[i]].cycle, static_cast<std::uint32_t>(k), i});
            }
            std::sort(group.order.begin(), group.order.end());
            for (const L2Group::Key& key : group.order) {
                DeferredReads& d = cores[key.core]->deferredReads;
                const std::uint32_t index = d.byClass[c][key.position];
                const DeferredReads::Read& r = d.reads[index];
                const LineFill f =
                    cores[key.core]->port.atCore(l2->access(r.address, r.cycle, r.arrive, group.counters, group.stamp));
                d.fills[index] = f;
                group.ready[key.core] = std::min(group.ready[key.core], f.ready);
            }
        }
    };
    if (groups == 1) answer(0);
    else parallelForEach(groups, answer, l2Affinity);  // a group's L2 sets stay in its thread's cache
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
void RtCore::Impl::rethrowFirstError() {
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
void RtCore::Impl::mergeRayTypes() {
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
    mergeByCycle(
        cursor, [&](std::size_t k, std::size_t i) { return cores[k]->activity[i].cycle; },
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

std::uint64_t RtCore::Impl::portsFree(std::uint64_t c) const {
    for (const auto& core : cores) c = std::max(c, core->port.channel.nextFree());
    return c;
}

void RtCore::Impl::checkRays(std::span<const SimRay> rays, std::size_t results, const char* what) {
    if (rays.size() != results) throw std::invalid_argument(std::string(what) + ": rays and results differ in size");
    if (rays.size() > UINT32_MAX / 2) throw std::invalid_argument(std::string(what) + ": too many rays");
    for (const SimRay& r : rays)
        if (r.rayType >= kMaxRayTypes)
            throw std::invalid_argument(std::string(what) + ": rayType " + std::to_string(r.rayType) +
                                        " >= " + std::to_string(kMaxRayTypes));
    if (scene.generation() != layoutGeneration) {
        if (layoutGeneration != ~std::uint64_t(0)) {
            for (auto& core : cores) core->cache.invalidate();
            if (l2) l2->invalidate();
        }
        layout.build(scene);
        layoutGeneration = scene.generation();
    }
}

void RtCore::Impl::run(std::span<const SimRay> rays, ProgrammableSide& programmable, std::span<SimRayResult> out) {
    checkRays(rays, out.size(), "RtCore::run");
    if (rays.empty()) return;
    // Step: the ray order before warp formation (gpu.rayOrder).
    batch.order.clear();
    if (config.gpu.rayOrder == RayOrder::DirectionOrigin) batch.order = directionOriginOrder(rays);
    const std::uint32_t w = config.core.warpWidth;
    const std::uint32_t warps = static_cast<std::uint32_t>((rays.size() + w - 1) / w);
    simulateBatch(rays, programmable, out, warps, [&] { tileGroups(warps); });
}

// Groups of a launch: warp w = threads [w * warpWidth, ...); its group k =
// the k-th rays of its threads, in thread order. batch.order maps the
// grouped rays back to the launch's.
void RtCore::Impl::launchGroups(std::span<const std::uint32_t> threads, std::uint32_t threadCount) {
    const std::uint32_t w = config.core.warpWidth;
    const auto n = static_cast<std::uint32_t>(threads.size());
    const auto warps = static_cast<std::uint32_t>((std::uint64_t(threadCount) + w - 1) / w);
    // Per thread, its rays in launch order (a counting sort by thread).
    std::vector<std::uint32_t> start(std::size_t(threadCount) + 1, 0);
    for (std::uint32_t t : threads) ++start[t + 1];
    for (std::uint32_t t = 0; t < threadCount; ++t) start[t + 1] += start[t];
    std::vector<std::uint32_t> byThread(n), fill(start.begin(), start.end() - 1);
    for (std::uint32_t i = 0; i < n; ++i) byThread[fill[threads[i]]++] = i;
    batch.groupFirst.clear();
    batch.groupSize.clear();
    batch.groupWarp.clear();
    batch.warpGroups.assign(std::size_t(warps) + 1, 0);
    batch.order.clear();
    batch.order.reserve(n);
    batch.rayGroup.resize(n);
    for (std::uint32_t warp = 0; warp < warps; ++warp) {
        batch.warpGroups[warp] = static_cast<std::uint32_t>(batch.groupFirst.size());
        const std::uint32_t t0 = warp * w, t1 = std::min(threadCount, t0 + w);
        std::uint32_t rounds = 0;
        for (std::uint32_t t = t0; t < t1; ++t) rounds = std::max(rounds, start[t + 1] - start[t]);
        for (std::uint32_t k = 0; k < rounds; ++k) {
            const auto group = static_cast<std::uint32_t>(batch.groupFirst.size());
            const auto first = static_cast<std::uint32_t>(batch.order.size());
            for (std::uint32_t t = t0; t < t1; ++t)
                if (start[t + 1] - start[t] > k) {
                    batch.rayGroup[batch.order.size()] = group;
                    batch.order.push_back(byThread[start[t] + k]);
                }
            batch.groupFirst.push_back(first);
            batch.groupSize.push_back(static_cast<std::uint32_t>(batch.order.size()) - first);
            batch.groupWarp.push_back(warp);
        }
    }
    batch.warpGroups[warps] = static_cast<std::uint32_t>(batch.groupFirst.size());
    batch.residentWarps = config.gpu.residentWarps;
    batch.nextTraceLatency = config.shader.nextTraceLatency;
    // gpu.rayOrder at launch level: the cores' input queues admit in key order.
    batch.reorderInput = config.gpu.rayOrder == RayOrder::DirectionOrigin;
    if (batch.reorderInput) {
        const std::vector<std::uint64_t> keys = directionOriginKeys(batch.rays);  // the launch's rays, launch order
        batch.rayKey.resize(n);
        for (std::uint32_t i = 0; i < n; ++i) batch.rayKey[i] = keys[batch.order[i]];
    }
}

void RtCore::Impl::runLaunch(std::span<const SimRay> rays, std::span<const std::uint32_t> threads,
                             std::uint32_t threadCount, ProgrammableSide& programmable, std::span<SimRayResult> out) {
    checkRays(rays, out.empty() ? rays.size() : out.size(), "RtCore::runLaunch");
    if (threads.size() != rays.size())
        throw std::invalid_argument("RtCore::runLaunch: rays and threads differ in size");
    if (threadCount > kMaxLaunchThreads)
        throw InputError("RtCore::runLaunch", "a launch of " + std::to_string(threadCount) + " threads (at most " +
                                                  std::to_string(kMaxLaunchThreads) + ")");
    for (std::uint32_t t : threads)
        if (t >= threadCount)
            throw std::invalid_argument("RtCore::runLaunch: thread " + std::to_string(t) + " >= the launch's " +
                                        std::to_string(threadCount) + " threads");
    if (rays.empty()) return;
    const std::uint32_t w = config.core.warpWidth;
    const auto warps = static_cast<std::uint32_t>((std::uint64_t(threadCount) + w - 1) / w);
    batch.order.clear();
    simulateBatch(rays, programmable, out, warps, [&] { launchGroups(threads, threadCount); });
}

// The common part of a batch and a launch: batch.order is set (empty = the
// caller's order), `makeGroups` fills the groups; then dispatch, simulation, results.
template <class MakeGroups>
void RtCore::Impl::simulateBatch(std::span<const SimRay> rays, ProgrammableSide& programmable,
                                 std::span<SimRayResult> out, std::uint32_t warps, MakeGroups&& makeGroups) {
    batch.rays = rays;
    makeGroups();
    batch.side = &programmable;
    batch.results = out;
    batch.raySteps.assign(rays.size(), 0);
    batch.groupSubmit.assign(batch.groupFirst.size(), 0);
    batch.groupRemaining = batch.groupSize;
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
    } catch (...) {
        abortBatch();
        throw;
    }
    batch.rays = {};
    batch.results = {};
    batch.side = nullptr;
}

// A side callback threw: drop the batch's rays; the clock stays at the cycle reached.
void RtCore::Impl::abortBatch() {
    now = portsFree(clock);
    for (auto& core : cores) core->port.defer(nullptr);
    mergeRayTypes();
    for (auto& core : cores) core->abortBatch(now);
    for (RayTypeStats& t : batch.rayTypes) t.inFlight = 0;
    batch.rays = {};
    batch.results = {};
    batch.side = nullptr;
}

void RtCore::Impl::resetStats() {
    const std::size_t types = batch.rayTypes.size();
    batch.rayTypes.assign(types, RayTypeStats{});
    frameStart = now;
    batches = 0;
    for (auto& core : cores) core->resetStats(now);
    if (l2) l2->resetStats();
}

void RtCore::Impl::reset() {
    now = 0;
    for (auto& core : cores) core->resetTime();
    if (l2) {
        l2->invalidate();
        l2->resetTime();
    }
    resetStats();
}

}  // namespace rtlab::rtcore_sim
