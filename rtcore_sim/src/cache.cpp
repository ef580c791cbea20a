#include <rtlab/rtcore_sim/cache.hpp>

#include <algorithm>
#include <bit>
#include <numeric>
#include <stdexcept>

namespace rtlab::rtcore_sim {

NodeCache::NodeCache(const CacheParams& params) : params_(params) {
    const std::uint64_t setBytes = std::uint64_t(params.lineBytes) * params.ways;
    sets_ = static_cast<std::uint32_t>(std::max<std::uint64_t>(params.sizeBytes / setBytes, 1));
    if (!std::has_single_bit(sets_) || !std::has_single_bit(params.lineBytes))
        throw std::invalid_argument("NodeCache: sets and line size must be powers of two");
    lineShift_ = static_cast<std::uint32_t>(std::countr_zero(params.lineBytes));
    unitShift_ = static_cast<std::uint32_t>(std::countr_zero(params.fillBytes()));
    sectorsPerLine_ = params.lineBytes / params.fillBytes();
    const std::size_t lines = std::size_t(sets_) * params.ways;
    tags_.assign(lines, kInvalid);
    valid_.assign(lines, 0);
    ready_.assign(lines * sectorsPerLine_, 0);
    used_.assign(lines, 0);
    prefetched_.assign(lines, 0);
}

void NodeCache::prefetch(const MemoryRange& range, std::uint64_t now, MemoryPort& port) {
    ++prefetchRequests;
    const std::uint64_t first = range.address >> lineShift_;
    const std::uint64_t last = (range.address + std::max<std::uint32_t>(range.bytes, 1) - 1) >> lineShift_;
    for (std::uint64_t line = first; line <= last; ++line) {
        const std::size_t base = std::size_t(line & (sets_ - 1)) * params_.ways;
        std::size_t victim = base;
        bool present = false;
        for (std::size_t i = base; i < base + params_.ways && !present; ++i) {
            present = tags_[i] == line;
            if (tags_[victim] != kInvalid && (tags_[i] == kInvalid || used_[i] < used_[victim])) victim = i;
        }
        if (present) continue;  // a present line is left alone, also when some of its sectors were never read
        ++prefetchLines;
        if (tags_[victim] != kInvalid) ++evictions;
        tags_[victim] = line;
        used_[victim] = ++stamp_;
        prefetched_[victim] = 1;
        valid_[victim] = ~0u;
        // The whole line, every sector of it, one read per fill unit (an L2 line may be smaller than this line).
        for (std::uint32_t k = 0; k < sectorsPerLine_; ++k) {
            const std::size_t slot = victim * sectorsPerLine_ + k;
            ready_[slot] =
                port.readLine((line << lineShift_) + (std::uint64_t(k) << unitShift_), params_.fillBytes(), now).ready;
            if (isDeferred(ready_[slot])) [[unlikely]]
                port.deferred()->ways.push_back(static_cast<std::uint32_t>(slot));
        }
    }
}

void NodeCache::invalidate() {
    std::fill(tags_.begin(), tags_.end(), kInvalid);
    ++invalidations;
}

LineFill NodeCache::accessUnit(std::uint64_t unit, std::uint64_t now, MemoryPort& port) {
    ++accesses;
    const std::uint32_t sectorShift = lineShift_ - unitShift_;
    const std::uint64_t line = unit >> sectorShift;
    const std::uint32_t sector = static_cast<std::uint32_t>(unit & (sectorsPerLine_ - 1));
    const std::size_t base = std::size_t(line & (sets_ - 1)) * params_.ways;
    const std::uint64_t hitReady = now + params_.hitLatency;
    // Step: the tag search alone (the common hit reads only the set's tags).
    const std::size_t end = base + params_.ways;
    std::size_t i = base;
    while (i < end && tags_[i] != line) ++i;
    if (i < end) {
        used_[i] = ++stamp_;
        if (prefetched_[i]) {
            ++prefetchHits;
            prefetched_[i] = 0;
        }
        const std::size_t slot = i * sectorsPerLine_ + sector;
        if (!((valid_[i] >> sector) & 1u)) [[unlikely]] {
            // A sector miss: the line is there, this sector was never read.
            ++misses;
            valid_[i] |= 1u << sector;
            const LineFill fill = port.readLine(unit << unitShift_, params_.fillBytes(), now);
            ready_[slot] = fill.ready;
            if (isDeferred(fill.ready)) [[unlikely]]
                port.deferred()->ways.push_back(static_cast<std::uint32_t>(slot));
            return fill;
        }
        ++hits;
        if (ready_[slot] > hitReady) {
            // A line whose read is deferred: whether this hit is pending is decided when it is answered.
            if (isDeferred(ready_[slot])) [[unlikely]]
                return LineFill{ready_[slot] | kDeferredHit, 0, 0};
            ++pendingHits;
            return LineFill{ready_[slot], 0, 0};
        }
        return LineFill{hitReady, 0, 0};
    }
    // Step: a miss. Victim: the first empty way, else the least recently used one.
    std::size_t victim = base;
    for (i = base; i < end; ++i)
        if (tags_[victim] != kInvalid && (tags_[i] == kInvalid || used_[i] < used_[victim])) victim = i;
    ++misses;
    if (tags_[victim] != kInvalid) ++evictions;
    tags_[victim] = line;
    used_[victim] = ++stamp_;
    prefetched_[victim] = 0;
    valid_[victim] = 1u << sector;
    const std::size_t slot = victim * sectorsPerLine_ + sector;
    const LineFill fill = port.readLine(unit << unitShift_, params_.fillBytes(), now);
    ready_[slot] = fill.ready;
    if (isDeferred(fill.ready)) [[unlikely]]
        port.deferred()->ways.push_back(static_cast<std::uint32_t>(slot));
    return fill;
}

LineFill NodeCache::fetch(const MemoryRange& range, std::uint64_t now, MemoryPort& port) {
    const std::uint64_t first = range.address >> unitShift_;
    const std::uint64_t last = (range.address + std::max<std::uint32_t>(range.bytes, 1) - 1) >> unitShift_;
    LineFill done{now, 0, 0};
    for (std::uint64_t line = first; line <= last; ++line) {
        const LineFill f = accessUnit(line, now, port);
        if (isDeferred(f.ready)) [[unlikely]] {
            // From here on the lines' times are kept as terms: the first is the
            // latest line so far (the result of the lines before), then one per line.
            std::vector<LineFill>& terms = port.deferred()->terms;
            const std::size_t begin = terms.size();
            terms.push_back(done);
            terms.push_back(f);
            for (++line; line <= last; ++line) terms.push_back(accessUnit(line, now, port));
            return LineFill{kDeferred | begin, terms.size() - begin, 0};
        }
        if (f.ready > done.ready) done = f;
    }
    return done;
}

LineFill NodeCache::evaluate(std::uint64_t now, const LineFill* terms, std::size_t count, const DeferredReads& reads) {
    const std::uint64_t hitReady = now + params_.hitLatency;
    LineFill done = terms[0];
    for (std::size_t i = 1; i < count; ++i) {
        LineFill f = terms[i];
        if (isDeferred(f.ready)) {
            const LineFill& answer = reads.fills[f.ready & kDeferredIndex];
            if (!(f.ready & kDeferredHit)) {
                f = answer;  // the miss that made the read
            } else if (answer.ready > hitReady) {
                ++pendingHits;  // a hit on a line still being filled (accessUnit's rule)
                f = LineFill{answer.ready, 0, 0};
            } else {
                f = LineFill{hitReady, 0, 0};
            }
        }
        if (f.ready > done.ready) done = f;
    }
    return done;
}

void NodeCache::resolve(const DeferredReads& reads) {
    for (const std::uint32_t way : reads.ways)
        if (isDeferred(ready_[way])) ready_[way] = reads.fills[ready_[way] & kDeferredIndex].ready;
}

SharedL2::SharedL2(const L2Params& l2, const DramParams& dram) : l2_(l2), dram_(dram) {
    const std::uint64_t setBytes = std::uint64_t(l2.lineBytes) * l2.ways * l2.banks;
    setsPerBank_ = static_cast<std::uint32_t>(std::max<std::uint64_t>(l2.sizeBytes / setBytes, 1));
    if (!std::has_single_bit(setsPerBank_) || !std::has_single_bit(l2.lineBytes))
        throw std::invalid_argument("SharedL2: sets per bank and line size must be powers of two");
    lineShift_ = static_cast<std::uint32_t>(std::countr_zero(l2.lineBytes));
    dramTransfer_ = (l2.lineBytes + dram.bytesPerCycle - 1) / dram.bytesPerCycle;
    const std::size_t ways = std::size_t(l2.banks) * setsPerBank_ * l2.ways;
    tags_.assign(ways, kInvalid);
    ready_.assign(ways, 0);
    used_.assign(ways, 0);
    banks_.assign(l2.banks, Port{});
    channels_.assign(dram.channels, Port{});
    classes_ = std::gcd(l2.banks, dram.channels);
}

void SharedL2::invalidate() {
    std::fill(tags_.begin(), tags_.end(), kInvalid);
    ++invalidations;
}

void SharedL2::resetStats() {
    counters = L2Counters{};
    invalidations = 0;
    for (Port& p : banks_) p.busy = 0;
    for (Port& p : channels_) p.busy = 0;
}

void SharedL2::resetTime() {
    for (Port& p : banks_) {
        p.free = 0;
        p.reserved.clear();
    }
    for (Port& p : channels_) {
        p.free = 0;
        p.reserved.clear();
    }
}

std::uint64_t SharedL2::reserve(Port& port, std::uint64_t made, std::uint64_t ready, std::uint32_t cycles) const {
    port.busy += cycles;
    if (l2_.serviceOrder == ServiceOrder::Made) {
        const std::uint64_t start = std::max(ready, port.free);
        port.free = start + cycles;
        return start;
    }
    // Step: reservations over by the time this request was made cannot delay
    // it or any later-made one (every request arrives after it is made).
    // (The reservations never overlap, so sorted by start they are sorted by end.)
    std::vector<Interval>& r = port.reserved;
    const auto endsAfter = [](std::uint64_t t) { return [t](const Interval& v) { return v.end <= t; }; };
    r.erase(r.begin(), std::partition_point(r.begin(), r.end(), endsAfter(made)));
    // Step: the first gap of `cycles` at or after `ready` between the reservations.
    std::uint64_t start = ready;
    auto i = std::partition_point(r.begin(), r.end(), endsAfter(start));
    for (; i != r.end() && i->start < start + cycles; ++i) start = std::max(start, i->end);
    r.insert(i, Interval{start, start + cycles});
    return start;
}

LineFill SharedL2::access(std::uint64_t address, std::uint64_t made, std::uint64_t arrive, L2Counters& counts,
                          std::uint64_t& stamp) {
    L2Counters& c = counts;
    ++c.accesses;
    const std::uint64_t line = address >> lineShift_;
    const std::uint32_t bank = static_cast<std::uint32_t>(line % l2_.banks);
    // Step: the bank, in l2.serviceOrder.
    const std::uint64_t start = reserve(banks_[bank], made, arrive, l2_.bankCycles);
    if (start > arrive) {
        ++c.bankConflicts;
        c.bankWaitCycles += start - arrive;
    }
    const std::uint64_t tagDone = start + l2_.hitLatency;

    // Step: the tag lookup in the line's set of its bank.
    const std::size_t set = std::size_t((line / l2_.banks) & (setsPerBank_ - 1));
    const std::size_t base = (std::size_t(bank) * setsPerBank_ + set) * l2_.ways;
    const std::size_t end = base + l2_.ways;
    std::size_t i = base;
    while (i < end && tags_[i] != line) ++i;
    if (i < end) {
        ++c.hits;
        used_[i] = ++stamp;
        if (ready_[i] > tagDone) {  // still being filled: wait for DRAM
            ++c.pendingHits;
            return LineFill{ready_[i], tagDone - arrive, ready_[i] - tagDone};
        }
        return LineFill{tagDone, tagDone - arrive, 0};
    }
    // Victim: the first empty way, else the least recently used one.
    std::size_t victim = base;
    for (i = base; i < end; ++i)
        if (tags_[victim] != kInvalid && (tags_[i] == kInvalid || used_[i] < used_[victim])) victim = i;
    // Step: a miss reads the whole line from its DRAM channel.
    ++c.misses;
    if (tags_[victim] != kInvalid) ++c.evictions;
    const std::uint32_t channel = static_cast<std::uint32_t>(line % dram_.channels);
    const std::uint64_t dramStart = reserve(channels_[channel], made, tagDone, dramTransfer_);
    c.dramQueueCycles += dramStart - tagDone;
    ++c.dramReads;
    c.dramReadBytes += l2_.lineBytes;
    const std::uint64_t filled = dramStart + dramTransfer_ + dram_.latency;
    tags_[victim] = line;
    used_[victim] = ++stamp;
    ready_[victim] = filled;
    return LineFill{filled, tagDone - arrive, filled - tagDone};
}

}  // namespace rtlab::rtcore_sim
