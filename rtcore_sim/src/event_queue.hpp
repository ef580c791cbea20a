#pragma once
// The event queue of one RT core: the (ray slot, phase) events of the timing model by cycle, run in the
// order they were scheduled (docs/rtcore-model.md, "Cycle phases"). Internal to rtcore_sim.
#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace rtlab::rtcore_sim {

// Events: (slot, phase) in a binary min-heap on (cycle, sequence number).
// Events of one cycle run in the order they were scheduled: every event
// carries its core's scheduling sequence number, and an event whose cycle is
// only known later (a fetch waiting for a deferred L2 read, host-parallel
// epochs) takes its number when the serial model would have scheduled it
// (reserve()) and is placed by it (scheduleAt()). A core has a few hundred
// events pending at most: one contiguous heap stays in the host's cache,
// where a timing wheel's buckets did not (one bucket per cycle, 30 cores).

// kGroupReady: `slot` is a residency slot whose warp's next group is ready.
enum Phase : std::uint32_t { kFetchDone = 0, kStackTraffic = 1, kStepDone = 2, kGroupReady = 3 };
constexpr std::uint32_t makeEvent(std::uint32_t slot, Phase phase) { return slot << 2 | phase; }

class EventQueue {
public:
    static constexpr unsigned kEventBits = 16;  // events are < 4 x 4096 (core.raySlots <= 4096)
    static constexpr std::uint64_t kEventMask = (std::uint64_t(1) << kEventBits) - 1;

    static std::uint32_t eventOf(std::uint64_t entry) { return static_cast<std::uint32_t>(entry & kEventMask); }

    void schedule(std::uint64_t cycle, std::uint32_t event) { scheduleAt(cycle, event, seq_++); }
    // A sequence number for an event scheduled later with scheduleAt.
    std::uint64_t reserve() { return seq_++; }
    void scheduleAt(std::uint64_t cycle, std::uint32_t event, std::uint64_t seq) {
        if (cycle < now_) throw std::logic_error("rtcore_sim: event scheduled in the past");
        heap_.push_back(Item{cycle, seq << kEventBits | event});
        std::push_heap(heap_.begin(), heap_.end(), Later{});
    }
    // The simulation is at `cycle` (no event may be scheduled before it).
    void advance(std::uint64_t cycle) { now_ = cycle; }
    // The next event of `cycle` in order, if any (events scheduled for `cycle` while they run follow).
    bool popDue(std::uint64_t cycle, std::uint32_t& event) {
        if (heap_.empty() || heap_.front().cycle != cycle) return false;
        std::pop_heap(heap_.begin(), heap_.end(), Later{});
        event = eventOf(heap_.back().entry);
        heap_.pop_back();
        return true;
    }
    // The next event to run, if any (whatever its cycle).
    bool peek(std::uint32_t& event) const {
        if (heap_.empty()) return false;
        event = eventOf(heap_.front().entry);
        return true;
    }
    // The first cycle after `from` with an event; false when there is none.
    bool nextAfter(std::uint64_t from, std::uint64_t& out) const {
        if (heap_.empty()) return false;
        out = std::max(heap_.front().cycle, from + 1);
        return true;
    }
    bool empty() const { return heap_.empty(); }
    void clear() { heap_.clear(); }

private:
    struct Item {
        std::uint64_t cycle, entry;
    };
    struct Later {
        bool operator()(const Item& a, const Item& b) const {
            return a.cycle != b.cycle ? a.cycle > b.cycle : a.entry > b.entry;
        }
    };
    std::vector<Item> heap_;
    std::uint64_t now_ = 0;
    std::uint64_t seq_ = 0;
};

}  // namespace rtlab::rtcore_sim
