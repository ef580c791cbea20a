#pragma once
// The event wheel of one RT core: the (ray slot, phase) events of the timing model by cycle, run in the
// order they were scheduled (docs/rtcore-model.md, "Cycle phases"). Internal to rtcore_sim.
#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace rtlab::rtcore_sim {

// Events: (slot, phase) in a timing wheel of kWheelSize cycles, farther ones
// in an overflow heap. Events of one cycle run in the order they were
// scheduled: every event carries its core's scheduling sequence number, and
// an event whose cycle is only known later (a fetch waiting for a deferred L2
// read, host-parallel epochs) takes its number when the serial model would
// have scheduled it (reserve()) and is inserted at its place (scheduleAt()).

// kGroupReady: `slot` is a residency slot whose warp's next group is ready.
enum Phase : std::uint32_t { kFetchDone = 0, kStackTraffic = 1, kStepDone = 2, kGroupReady = 3 };
constexpr std::uint32_t makeEvent(std::uint32_t slot, Phase phase) { return slot << 2 | phase; }

class EventWheel {
public:
    static constexpr std::uint64_t kSize = 4096;
    static constexpr unsigned kEventBits = 16;  // events are < 4 x 4096 (core.raySlots <= 4096)
    static constexpr std::uint64_t kEventMask = (std::uint64_t(1) << kEventBits) - 1;

    EventWheel() : buckets_(kSize) {}

    static std::uint32_t eventOf(std::uint64_t entry) { return static_cast<std::uint32_t>(entry & kEventMask); }

    void schedule(std::uint64_t cycle, std::uint32_t event) { scheduleAt(cycle, event, seq_++); }
    // A sequence number for an event scheduled later with scheduleAt.
    std::uint64_t reserve() { return seq_++; }
    void scheduleAt(std::uint64_t cycle, std::uint32_t event, std::uint64_t seq) {
        const std::uint64_t entry = seq << kEventBits | event;
        if (cycle - base_ < kSize) [[likely]] {  // also false for cycle < base_ (wraps around)
            place(cycle, entry);
        } else {
            scheduleFar(cycle, entry);
        }
    }
    // The window moves to [cycle, cycle + kSize); overflow events now inside
    // it join their buckets in (cycle, sequence) order.
    void advance(std::uint64_t cycle) {
        base_ = cycle;
        while (!overflow_.empty() && overflow_.front().cycle < base_ + kSize) {
            std::pop_heap(overflow_.begin(), overflow_.end(), Later{});
            const Far far = overflow_.back();
            overflow_.pop_back();
            place(far.cycle, far.entry);
        }
    }
    std::vector<std::uint64_t>& bucket(std::uint64_t cycle) { return buckets_[cycle & (kSize - 1)]; }
    void clearBucket(std::uint64_t cycle) {
        const std::size_t b = cycle & (kSize - 1);
        inWheel_ -= buckets_[b].size();
        buckets_[b].clear();
        bits_[b >> 6] &= ~(std::uint64_t(1) << (b & 63));
    }
    // The first cycle after `from` with an event; false when there is none.
    bool nextAfter(std::uint64_t from, std::uint64_t& out) const {
        if (inWheel_ > 0) {
            // Scan the bitmap from from+1, wrapping once around the wheel.
            for (std::uint64_t d = 1; d < kSize;) {
                const std::uint64_t c = from + d;
                const std::size_t b = c & (kSize - 1);
                const std::uint64_t word = bits_[b >> 6] >> (b & 63);
                if (word != 0) {
                    const std::uint64_t skip = static_cast<std::uint64_t>(std::countr_zero(word));
                    if (d + skip < kSize) {
                        out = c + skip;
                        return true;
                    }
                    break;
                }
                d += 64 - (b & 63);
            }
        }
        if (!overflow_.empty()) {
            out = overflow_.front().cycle;
            return true;
        }
        return false;
    }
    bool empty() const { return inWheel_ == 0 && overflow_.empty(); }
    [[gnu::noinline]] void scheduleFar(std::uint64_t cycle, std::uint64_t entry) {
        if (cycle < base_) throw std::logic_error("rtcore_sim: event scheduled in the past");
        overflow_.push_back(Far{cycle, entry});
        std::push_heap(overflow_.begin(), overflow_.end(), Later{});
    }
    void clear() {
        for (auto& b : buckets_) b.clear();
        bits_.fill(0);
        overflow_.clear();
        inWheel_ = 0;
    }

private:
    struct Far {
        std::uint64_t cycle, entry;
    };
    struct Later {
        bool operator()(const Far& a, const Far& b) const {
            return a.cycle != b.cycle ? a.cycle > b.cycle : a.entry > b.entry;
        }
    };
    // Entries of a bucket stay sorted by sequence number: new events append,
    // a deferred one is inserted at its place.
    void place(std::uint64_t cycle, std::uint64_t entry) {
        const std::size_t b = cycle & (kSize - 1);
        std::vector<std::uint64_t>& bucket = buckets_[b];
        if (bucket.empty() || bucket.back() < entry) [[likely]]
            bucket.push_back(entry);
        else bucket.insert(std::upper_bound(bucket.begin(), bucket.end(), entry), entry);
        bits_[b >> 6] |= std::uint64_t(1) << (b & 63);
        ++inWheel_;
    }

    std::vector<std::vector<std::uint64_t>> buckets_;
    std::array<std::uint64_t, kSize / 64> bits_{};
    std::vector<Far> overflow_;
    std::uint64_t base_ = 0;
    std::uint64_t seq_ = 0;
    std::size_t inWheel_ = 0;
};

}  // namespace rtlab::rtcore_sim
