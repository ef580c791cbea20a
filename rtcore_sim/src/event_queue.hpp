#pragma once
// The event queue of one RT core: the (ray slot, phase) events of the timing model by cycle, run in the
// order they were scheduled (docs/rtcore-model.md, "Cycle phases"). Internal to rtcore_sim.
#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace rtlab::rtcore_sim {

// Events: (slot, phase) in a 4-ary min-heap on (cycle, sequence number),
// one 128-bit key each (cycle in the high word: one comparison, no branch
// on the tie). Events of one cycle run in the order they were scheduled:
// every event carries its core's scheduling sequence number, and an event
// whose cycle is only known later (a fetch waiting for a deferred L2 read,
// host-parallel epochs) takes its number when the serial model would have
// scheduled it (reserve()) and is placed by it (scheduleAt()). The keys are
// unique, so the order events run in does not depend on the heap's shape. A
// core has a few hundred events pending at most: one contiguous heap stays
// in the host's cache, where a timing wheel's buckets did not (one bucket per
// cycle, 30 cores); four children per node halve the levels of a binary heap.

// kGroupReady: `slot` is a residency slot whose warp's next group is ready.
enum Phase : std::uint32_t { kFetchDone = 0, kStackTraffic = 1, kStepDone = 2, kGroupReady = 3 };
constexpr std::uint32_t makeEvent(std::uint32_t slot, Phase phase) { return slot << 2 | phase; }

class EventQueue {
public:
    static constexpr unsigned kEventBits = 16;  // events are < 4 x 4096 (core.raySlots <= 4096)
    static constexpr std::uint64_t kEventMask = (std::uint64_t(1) << kEventBits) - 1;

    void schedule(std::uint64_t cycle, std::uint32_t event) { scheduleAt(cycle, event, seq_++); }
    // A sequence number for an event scheduled later with scheduleAt.
    std::uint64_t reserve() { return seq_++; }
    void scheduleAt(std::uint64_t cycle, std::uint32_t event, std::uint64_t seq) {
        if (cycle < now_) throw std::logic_error("rtcore_sim: event scheduled in the past");
        const Key key = Key(cycle) << 64 | Key(seq << kEventBits | event);
        // Step: sift up from the new leaf.
        std::size_t i = heap_.size();
        heap_.push_back(key);
        while (i > 0) {
            const std::size_t parent = (i - 1) / kArity;
            if (heap_[parent] < key) break;
            heap_[i] = heap_[parent];
            i = parent;
        }
        heap_[i] = key;
    }
    // The simulation is at `cycle` (no event may be scheduled before it).
    void advance(std::uint64_t cycle) { now_ = cycle; }
    // The next event of `cycle` in order, if any (events scheduled for `cycle` while they run follow).
    bool popDue(std::uint64_t cycle, std::uint32_t& event) {
        if (heap_.empty() || cycleOf(heap_.front()) != cycle) return false;
        event = eventOf(heap_.front());
        // Step: the last leaf sifts down from the root.
        const Key last = heap_.back();
        heap_.pop_back();
        const std::size_t n = heap_.size();
        if (n == 0) return true;
        std::size_t i = 0;
        for (;;) {
            const std::size_t first = kArity * i + 1;
            if (first >= n) break;
            // The least child, without a branch per comparison (their outcome is a coin toss).
            std::size_t least = first;
            Key best = heap_[first];
            const std::size_t end = first + kArity < n ? first + kArity : n;
            for (std::size_t c = first + 1; c < end; ++c) {
                const Key k = heap_[c];
                const bool less = __builtin_expect_with_probability(k < best, 1, 0.5);
                least = less ? c : least;
                best = less ? k : best;
            }
            if (last < best) break;
            heap_[i] = best;
            i = least;
        }
        heap_[i] = last;
        return true;
    }
    // The next event to run, if any (whatever its cycle).
    bool peek(std::uint32_t& event) const {
        if (heap_.empty()) return false;
        event = eventOf(heap_.front());
        return true;
    }
    // The first cycle after `from` with an event; false when there is none.
    bool nextAfter(std::uint64_t from, std::uint64_t& out) const {
        if (heap_.empty()) return false;
        out = std::max(cycleOf(heap_.front()), from + 1);
        return true;
    }
    bool empty() const { return heap_.empty(); }
    void clear() { heap_.clear(); }

private:
    __extension__ typedef unsigned __int128 Key;
    static constexpr std::size_t kArity = 4;
    static std::uint64_t cycleOf(Key k) { return static_cast<std::uint64_t>(k >> 64); }
    static std::uint32_t eventOf(Key k) {
        return static_cast<std::uint32_t>(static_cast<std::uint64_t>(k) & kEventMask);
    }
    std::vector<Key> heap_;
    std::uint64_t now_ = 0;
    std::uint64_t seq_ = 0;
};

}  // namespace rtlab::rtcore_sim
