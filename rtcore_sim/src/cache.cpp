#include <rtlab/rtcore_sim/cache.hpp>

#include <algorithm>
#include <bit>
#include <stdexcept>

namespace rtlab::rtcore_sim {

NodeCache::NodeCache(const CacheParams& params) : params_(params) {
    const std::uint64_t setBytes = std::uint64_t(params.lineBytes) * params.ways;
    sets_ = static_cast<std::uint32_t>(std::max<std::uint64_t>(params.sizeBytes / setBytes, 1));
    if (!std::has_single_bit(sets_) || !std::has_single_bit(params.lineBytes))
        throw std::invalid_argument("NodeCache: sets and line size must be powers of two");
    lineShift_ = static_cast<std::uint32_t>(std::countr_zero(params.lineBytes));
    const std::size_t lines = std::size_t(sets_) * params.ways;
    tags_.assign(lines, kInvalid);
    ready_.assign(lines, 0);
    used_.assign(lines, 0);
}

void NodeCache::invalidate() {
    std::fill(tags_.begin(), tags_.end(), kInvalid);
    ++invalidations;
}

std::uint64_t NodeCache::accessLine(std::uint64_t line, std::uint64_t now, MemoryChannel& memory) {
    ++accesses;
    const std::size_t base = std::size_t(line & (sets_ - 1)) * params_.ways;
    const std::uint64_t hitReady = now + params_.hitLatency;
    std::size_t victim = base;
    for (std::size_t i = base; i < base + params_.ways; ++i) {
        if (tags_[i] == line) {
            ++hits;
            used_[i] = ++stamp_;
            if (ready_[i] > hitReady) {
                ++pendingHits;
                return ready_[i];
            }
            return hitReady;
        }
        // Victim: the first empty way, else the least recently used one.
        if (tags_[victim] != kInvalid && (tags_[i] == kInvalid || used_[i] < used_[victim])) victim = i;
    }
    ++misses;
    if (tags_[victim] != kInvalid) ++evictions;
    tags_[victim] = line;
    used_[victim] = ++stamp_;
    ready_[victim] = memory.read(now, params_.lineBytes);
    return ready_[victim];
}

std::uint64_t NodeCache::fetch(const MemoryRange& range, std::uint64_t now, MemoryChannel& memory) {
    const std::uint64_t first = range.address >> lineShift_;
    const std::uint64_t last = (range.address + std::max<std::uint32_t>(range.bytes, 1) - 1) >> lineShift_;
    std::uint64_t ready = now;
    for (std::uint64_t line = first; line <= last; ++line) ready = std::max(ready, accessLine(line, now, memory));
    return ready;
}

}  // namespace rtlab::rtcore_sim
