#pragma once
// The timing model's memory side (docs/rtcore-model.md, "Node cache and
// memory" and "GPU level"): per core a set-associative LRU node cache (L1)
// in front of the core's memory port; in l2 mode cache the port leads to a
// banked L2 shared by all cores, backed by DRAM channels. Every resource
// takes its requests in the order they are made (cycle, then core index)
// and reserves each an interval of its time: from when both the request
// and the resource are there (l2.serviceOrder made), or in the first idle
// interval after the request arrives (arrival).
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
    // A read requested at `now` whose data comes from further down: the end
    // of its transfer slot (the latency is added by the caller).
    std::uint64_t transfer(std::uint64_t now, std::uint32_t bytes) {
        ++reads;
        readBytes += bytes;
        return reserve(now, bytes);
    }
    std::uint32_t latency() const { return params_.latency; }
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

// When a line read below a node cache is there, and how many of its cycles
// were spent in the L2 (bank wait + hit latency) and in DRAM (channel wait,
// transfer, latency): the latency breakdown's l2 and dram terms.
struct LineFill {
    std::uint64_t ready = 0;
    std::uint64_t l2Cycles = 0;
    std::uint64_t dramCycles = 0;
};

// Host-parallel epochs (docs/rtcore-model.md, "Host threads"): while the
// cores run on several host threads, a core's L2 reads are not answered at
// once but logged, and answered between epochs in the order the serial model
// makes them (cycle, core index, the core's own order). Until then the
// data-ready cycle of such a read is a placeholder, kDeferred | read index:
// in a node-cache way, and in the per-line times of a fetch that waits for
// it. No decision inside an epoch depends on a placeholder's value (every
// answer lands after the epoch ends), so the answers, filled in afterwards,
// give exactly the serial model's cycles.
inline constexpr std::uint64_t kDeferred = std::uint64_t(1) << 63;
inline constexpr std::uint64_t kDeferredHit = std::uint64_t(1) << 62;  // fetch term: a hit on such a line
inline constexpr std::uint64_t kDeferredIndex = 0xffffffffu;
inline bool isDeferred(std::uint64_t ready) { return (ready & kDeferred) != 0; }

// One core's deferred L2 reads of an epoch and what waits for them.
struct DeferredReads {
    struct Read {
        std::uint64_t cycle;    // when the core made it (the serial order's first key)
        std::uint64_t address;  // byte address of the node-cache line
        std::uint64_t arrive;   // end of its transfer slot on the core's port (the L2 arrival)
    };
    std::vector<Read> reads;                          // in the order made
    std::vector<std::vector<std::uint32_t>> byClass;  // per L2 line class (SharedL2::classOf): its reads, in order
    std::vector<LineFill> fills;                      // the answers, per read, data at the core (filled between epochs)
    std::vector<LineFill> terms;                      // per-line times of fetches that wait for a deferred read
    std::vector<std::uint32_t> ways;  // node-cache slots (way x sectors + sector) given a placeholder (may repeat)
    bool empty() const { return reads.empty(); }
    void clear() {
        reads.clear();
        for (auto& c : byClass) c.clear();
        fills.clear();
        terms.clear();
        ways.clear();
    }
};

// The L2 shared by all cores (l2 mode cache) with the DRAM channels behind it.
// Banks: line l (address / l2.lineBytes) is in bank l mod banks, set
// (l / banks) mod setsPerBank; an access occupies its bank l2.bankCycles
// cycles from start = max(arrival, bank free) (l2.serviceOrder arrival:
// the first idle l2.bankCycles at or after arrival); a hit's data leaves at
// start + hitLatency (a line still being filled: at its fill cycle). A miss
// allocates the line (LRU victim) and reads it from DRAM channel l mod channels
// from max(start + hitLatency, channel free) (arrival: the first idle
// interval from start + hitLatency), for ceil(l2.lineBytes /
// dram.bytesPerCycle) cycles; the line is there dram.latency cycles later.
// Counters of the L2 and the DRAM behind it.
struct L2Counters {
    std::uint64_t accesses = 0, hits = 0, pendingHits = 0, misses = 0, evictions = 0;
    std::uint64_t bankConflicts = 0;   // accesses that found their bank busy
    std::uint64_t bankWaitCycles = 0;  // sum of their waits
    std::uint64_t dramReads = 0, dramReadBytes = 0, dramQueueCycles = 0;
    void add(const L2Counters& o) {
        accesses += o.accesses;
        hits += o.hits;
        pendingHits += o.pendingHits;
        misses += o.misses;
        evictions += o.evictions;
        bankConflicts += o.bankConflicts;
        bankWaitCycles += o.bankWaitCycles;
        dramReads += o.dramReads;
        dramReadBytes += o.dramReadBytes;
        dramQueueCycles += o.dramQueueCycles;
    }
};

class SharedL2 {
public:
    SharedL2(const L2Params& l2, const DramParams& dram);

    // A read of `address` made at cycle `made` that reaches the L2 at `arrive` (>= made).
    LineFill access(std::uint64_t address, std::uint64_t made, std::uint64_t arrive) {
        return access(address, made, arrive, counters, stamp_);
    }
    // Lines of different classes (line mod classes(), classes = gcd(banks,
    // channels)) share no bank, no set and no DRAM channel, so the accesses
    // of different classes may be made on different host threads, each with
    // its own counters (added to `counters` afterwards) and LRU stamp (started
    // at stamp(), the largest given back with setStamp: only the order of the
    // stamps within a set matters).
    // Reads must come in the order made (non-decreasing `made`) since the
    // last resetTime().
    LineFill access(std::uint64_t address, std::uint64_t made, std::uint64_t arrive, L2Counters& counts,
                    std::uint64_t& stamp);
    std::uint32_t classes() const { return classes_; }
    std::uint32_t classOf(std::uint64_t address) const {
        return static_cast<std::uint32_t>((address >> lineShift_) % classes_);
    }
    std::uint64_t stamp() const { return stamp_; }
    void setStamp(std::uint64_t stamp) { stamp_ = stamp; }
    void invalidate();
    void resetStats();
    void resetTime();
    std::uint32_t banks() const { return l2_.banks; }
    std::uint32_t channels() const { return dram_.channels; }

    L2Counters counters;
    std::uint64_t invalidations = 0;
    std::uint64_t bankBusyCycles(std::uint32_t bank) const { return banks_[bank].busy; }
    std::uint64_t channelBusyCycles(std::uint32_t channel) const { return channels_[channel].busy; }

private:
    static constexpr std::uint64_t kInvalid = ~std::uint64_t(0);
    L2Params l2_;
    DramParams dram_;
    std::uint32_t setsPerBank_ = 1;
    std::uint32_t lineShift_ = 7;
    std::uint32_t dramTransfer_ = 1;
    std::uint32_t classes_ = 1;
    std::vector<std::uint64_t> tags_, ready_, used_;  // per way, [bank][set][way]
    // A bank's or DRAM channel's state, one host cache line each: the
    // classes' accesses on different host threads share no line.
    struct Interval {
        std::uint64_t start, end;
    };
    struct alignas(64) Port {
        std::uint64_t free = 0;  // order made: the first cycle it takes a new request
        std::uint64_t busy = 0;  // cycles busy since resetStats
        // Order arrival: the reservations that may still delay a request, by start.
        std::vector<Interval> reserved;
    };
    // The start of a request ready at `ready` (made at `made`) that occupies
    // `port` for `cycles`, under l2.serviceOrder; the port is reserved.
    std::uint64_t reserve(Port& port, std::uint64_t made, std::uint64_t ready, std::uint32_t cycles) const;
    std::vector<Port> banks_, channels_;
    std::uint64_t stamp_ = 0;
};

// A core's path below its node cache: its memory port (memory.*) and, in l2
// mode cache, the shared L2. Mode ideal: a read's data is there memory.latency
// cycles after its transfer slot (the single-core model). Mode cache: the
// request reaches the L2 at the end of its transfer slot and its data is at
// the core memory.latency cycles after it leaves the L2.
class MemoryPort {
public:
    MemoryPort(const MemoryParams& memory, SharedL2* l2, std::uint32_t l2HitLatency)
        : channel(memory), l2_(l2), l2HitLatency_(l2HitLatency) {}

    LineFill readLine(std::uint64_t address, std::uint32_t bytes, std::uint64_t now) {
        if (!l2_) return LineFill{channel.read(now, bytes), 0, 0};
        const std::uint64_t arrive = channel.transfer(now, bytes);
        if (deferred_) [[unlikely]] {
            const std::uint64_t index = deferred_->reads.size();
            deferred_->reads.push_back(DeferredReads::Read{now, address, arrive});
            deferred_->byClass[l2_->classOf(address)].push_back(static_cast<std::uint32_t>(index));
            return LineFill{kDeferred | index, 0, 0};
        }
        return atCore(l2_->access(address, now, arrive));
    }
    // The L2's answer to a read, as the time its data is at the core.
    LineFill atCore(LineFill fromL2) const {
        fromL2.ready += channel.latency();
        return fromL2;
    }
    // Host-parallel epochs: L2 reads are logged in `reads` instead of
    // answered (nullptr: answered at once). Mode ideal never defers.
    void defer(DeferredReads* reads) {
        deferred_ = l2_ ? reads : nullptr;
        if (deferred_) deferred_->byClass.resize(l2_->classes());
    }
    DeferredReads* deferred() const { return deferred_; }
    // The shortest time from a line read made at cycle c to its data at the
    // core in mode cache: port transfer + L2 hit latency + memory.latency
    // (a bank wait, DRAM or a busy port only add to it).
    std::uint64_t minReadLatency(std::uint32_t lineBytes) const {
        return channel.transferCycles(lineBytes) + std::uint64_t(l2HitLatency_) + channel.latency();
    }
    // Stack refills: mode cache assumes they hit in the L2 (no bank, no allocation).
    std::uint64_t readStack(std::uint64_t now, std::uint32_t bytes) {
        return channel.read(now, bytes) + (l2_ ? l2HitLatency_ : 0);
    }
    void writeStack(std::uint64_t now, std::uint32_t bytes) { channel.write(now, bytes); }

    MemoryChannel channel;

private:
    SharedL2* l2_;
    std::uint32_t l2HitLatency_;
    DeferredReads* deferred_ = nullptr;
};

// Set-associative node cache with LRU replacement. Lines are allocated at
// the miss (the data arrives later); a hit on a line still being filled waits
// for its data (a "pending hit", merged into the outstanding miss). With
// cache.sectorBytes, a line is a tag over sectors: a fetch looks up each
// sector it touches; a sector of a present line that was never read is a
// sector miss (read alone); a line's allocation evicts all its sectors.
// Accesses, hits and misses then count sectors.
class NodeCache {
public:
    explicit NodeCache(const CacheParams& params);

    // Reads `range` at cycle `now`: every line it touches is looked up in
    // address order, misses go to `port`; returns the cycle all its data is
    // there, with the L2 / DRAM parts of the line that came last.
    // With deferred L2 reads (MemoryPort::defer), a fetch that waits for one
    // returns {kDeferred | first term, term count, 0}: its per-line times are
    // port.deferred()->terms[first, first + count), to be evaluated by
    // evaluate() once the reads are answered.
    LineFill fetch(const MemoryRange& range, std::uint64_t now, MemoryPort& port);
    // The result of a deferred fetch made at `now`, the reads answered
    // (counts its pending hits, as fetch() would have).
    LineFill evaluate(std::uint64_t now, const LineFill* terms, std::size_t count, const DeferredReads& reads);
    // Replaces the placeholders of answered reads in the cache's ways.
    void resolve(const DeferredReads& reads);
    // One unit (address / fill unit: a line, or a sector of a sectored
    // cache) at `now`: the cycle its data is there.
    LineFill accessUnit(std::uint64_t unit, std::uint64_t now, MemoryPort& port);

    // Reads `range` ahead of demand at `now`: every line it touches that is
    // not in the cache is allocated and filled through `port` (LRU victim);
    // lines present or pending are left alone. A later demand hit on a line
    // brought in this way counts as a prefetchHit.
    void prefetch(const MemoryRange& range, std::uint64_t now, MemoryPort& port);

    void invalidate();  // every line invalid (the BVHs changed)
    void resetStats() {
        accesses = hits = pendingHits = misses = evictions = prefetchRequests = prefetchLines = prefetchHits = 0;
    }
    std::uint32_t lineBytes() const { return params_.lineBytes; }
    std::uint32_t sets() const { return sets_; }

    std::uint64_t accesses = 0;
    std::uint64_t hits = 0;         // includes pendingHits
    std::uint64_t pendingHits = 0;  // hits on a line whose data was still on its way
    std::uint64_t misses = 0;
    std::uint64_t evictions = 0;  // valid lines replaced
    std::uint64_t invalidations = 0;
    std::uint64_t prefetchRequests = 0;  // prefetch() calls
    std::uint64_t prefetchLines = 0;     // lines they read (not already present)
    std::uint64_t prefetchHits = 0;      // first demand hits on prefetched lines

private:
    static constexpr std::uint64_t kInvalid = ~std::uint64_t(0);
    CacheParams params_;
    std::vector<std::uint8_t> prefetched_;  // per way: filled by prefetch(), not yet hit by demand
    std::uint32_t sets_ = 1;
    std::uint32_t lineShift_ = 6;
    std::uint32_t unitShift_ = 6;       // log2 of the fill unit (a sector, or the line)
    std::uint32_t sectorsPerLine_ = 1;  // 1: unsectored
    std::vector<std::uint64_t> tags_;   // line number per way, kInvalid when empty
    std::vector<std::uint32_t> valid_;  // per way: its sectors read (sectored caches)
    std::vector<std::uint64_t> ready_;  // per way and sector: cycle its data is there
    std::vector<std::uint64_t> used_;   // LRU stamp
    std::uint64_t stamp_ = 0;
};

}  // namespace rtlab::rtcore_sim
