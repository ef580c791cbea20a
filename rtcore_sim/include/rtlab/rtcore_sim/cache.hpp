#pragma once
// The timing model's memory side (docs/rtcore-model.md, "Node cache and
// memory"): a set-associative LRU node cache in front of one memory channel.
// Requests must arrive in non-decreasing cycle order (the simulator issues
// them in event order), which makes the channel's first-come-first-served
// schedule exact.
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/rtcore_sim/layout.hpp>

#include <cstdint>
#include <vector>

namespace rtlab::rtcore_sim {

// One channel: a request of B bytes occupies it ceil(B / bytesPerCycle)
// cycles, starting when both the request and the channel are there; a read's
// data arrives `latency` cycles after its transfer slot ends.
class MemoryChannel {
public:
    explicit MemoryChannel(const MemoryParams& params) : params_(params) {}

    std::uint32_t transferCycles(std::uint32_t bytes) const {
        return (bytes + params_.bytesPerCycle - 1) / params_.bytesPerCycle;
    }
    // A read requested at `now`: the cycle its data arrives.
    std::uint64_t read(std::uint64_t now, std::uint32_t bytes) {
        ++reads;
        readBytes += bytes;
        return reserve(now, bytes) + params_.latency;
    }
    // A write (fire and forget: it only occupies the channel).
    void write(std::uint64_t now, std::uint32_t bytes) {
        ++writes;
        writeBytes += bytes;
        reserve(now, bytes);
    }
    // The first cycle the channel is free.
    std::uint64_t nextFree() const { return nextFree_; }
    void resetStats() { reads = writes = readBytes = writeBytes = busyCycles = queueCycles = 0; }
    void resetTime() { nextFree_ = 0; }

    std::uint64_t reads = 0, writes = 0, readBytes = 0, writeBytes = 0;
    std::uint64_t busyCycles = 0;   // sum of transfer cycles
    std::uint64_t queueCycles = 0;  // sum over requests of cycles waited for the channel

private:
    // Returns the end of the request's transfer slot.
    std::uint64_t reserve(std::uint64_t now, std::uint32_t bytes) {
        const std::uint64_t start = now > nextFree_ ? now : nextFree_;
        const std::uint32_t transfer = transferCycles(bytes);
        queueCycles += start - now;
        busyCycles += transfer;
        nextFree_ = start + transfer;
        return nextFree_;
    }

    MemoryParams params_;
    std::uint64_t nextFree_ = 0;
};

// Set-associative node cache with LRU replacement. Lines are allocated at
// the miss (the data arrives later); a hit on a line still being filled waits
// for its data (a "pending hit", merged into the outstanding miss).
class NodeCache {
public:
    explicit NodeCache(const CacheParams& params);

    // Reads `range` at cycle `now`: every line it touches is looked up in
    // address order, misses go to `memory`; returns the cycle all its data is there.
    std::uint64_t fetch(const MemoryRange& range, std::uint64_t now, MemoryChannel& memory);
    // One line (address / lineBytes) at `now`: the cycle its data is there.
    std::uint64_t accessLine(std::uint64_t line, std::uint64_t now, MemoryChannel& memory);

    void invalidate();  // every line invalid (the BVHs changed)
    void resetStats() { accesses = hits = pendingHits = misses = evictions = 0; }
    std::uint32_t lineBytes() const { return params_.lineBytes; }
    std::uint32_t sets() const { return sets_; }

    std::uint64_t accesses = 0;
    std::uint64_t hits = 0;         // includes pendingHits
    std::uint64_t pendingHits = 0;  // hits on a line whose data was still on its way
    std::uint64_t misses = 0;
    std::uint64_t evictions = 0;    // valid lines replaced
    std::uint64_t invalidations = 0;

private:
    static constexpr std::uint64_t kInvalid = ~std::uint64_t(0);
    CacheParams params_;
    std::uint32_t sets_ = 1;
    std::uint32_t lineShift_ = 6;
    std::vector<std::uint64_t> tags_;   // line number per way, kInvalid when empty
    std::vector<std::uint64_t> ready_;  // cycle the line's data is there
    std::vector<std::uint64_t> used_;   // LRU stamp
    std::uint64_t stamp_ = 0;
};

}  // namespace rtlab::rtcore_sim
