// The stats tree of RtCore::statsJson (docs/rtcore-model.md, "Statistics"): one core's tree, or all cores'
// merged, and the GPU's top level with the ray types, the per-core trees and the shared L2 and DRAM.
#include "gpu_level.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim {
namespace {

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

    out["submission"] = {
        {"warpWidth", config.core.warpWidth},
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
    out["shader"] = {
        {"anyHitCalls", stats.anyHitCalls}, {"intersectionCalls", stats.intersectionCalls}, {"cycles", stats.shader}};
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
    out["simd"] = {
        {"warps", stats.warpsCompleted},
        {"warpSteps", stats.warpSteps},
        {"raySteps", stats.raySteps},
        {"activeRaysPerWarpStep", stats.activeRaysPerWarpStep.toJson()},
        {"efficiency", rate(double(stats.raySteps), double(stats.warpLanes))},
        {"laneFill", rate(double(stats.raysCompleted), double(stats.warpsCompleted) * config.core.warpWidth)}};
    return out;
}

}  // namespace

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

    out["gpu"] = {
        {"cores", n}, {"dispatch", toString(config.gpu.dispatch)}, {"rayOrder", toString(config.gpu.rayOrder)}};
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
        std::uint64_t bankBusy = 0, bankMax = 0;
        for (std::uint32_t b = 0; b < l2->banks(); ++b) {
            bankBusy += l2->bankBusyCycles(b);
            bankMax = std::max(bankMax, l2->bankBusyCycles(b));
        }
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
        std::uint64_t chBusy = 0, chMax = 0;
        for (std::uint32_t ch = 0; ch < l2->channels(); ++ch) {
            chBusy += l2->channelBusyCycles(ch);
            chMax = std::max(chMax, l2->channelBusyCycles(ch));
        }
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

}  // namespace rtlab::rtcore_sim
