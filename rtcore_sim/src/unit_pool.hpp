#pragma once
// UnitPool: the box-test, primitive or instance-transform units of one RT core, each kind a pool of identical
// pipelined units (docs/rtcore-model.md, "One traversal step"). Internal to rtcore_sim.
#include <algorithm>
#include <cstdint>
#include <vector>

namespace rtlab::rtcore_sim {

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

}  // namespace rtlab::rtcore_sim
