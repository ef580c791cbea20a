#pragma once
// Statistics building blocks of the timing model: raw counters are collected
// during simulation, derived values (means, rates) are computed when the
// stats tree is dumped (gem5 style).
#include <nlohmann/json.hpp>

#include <cstdint>
#include <vector>

namespace rtlab::rtcore_sim {

// A distribution of non-negative integers with weights.
//   Linear: one bucket per value 0 .. linearBuckets-1, then one overflow bucket
//   Log2:   bucket 0 = {0}, bucket k = [2^(k-1), 2^k)
// Dumped as {"count", "mean", "min", "max", "scheme", "buckets": [[lo, hi, weight], ...]}
// (non-empty buckets only, hi exclusive; count = total weight).
class Histogram {
public:
    enum class Scheme : std::uint8_t { Linear, Log2 };
    explicit Histogram(Scheme scheme = Scheme::Log2, std::uint32_t linearBuckets = 0);

    void add(std::uint64_t value, std::uint64_t weight = 1);
    void clear();
    // Adds another histogram of the same scheme (the sum of both distributions).
    void merge(const Histogram& other);

    std::uint64_t count() const { return count_; }
    std::uint64_t max() const { return count_ ? max_ : 0; }
    std::uint64_t min() const { return count_ ? min_ : 0; }
    double sum() const { return sum_; }
    double mean() const { return count_ ? sum_ / double(count_) : 0.0; }
    nlohmann::json toJson() const;

private:
    Scheme scheme_;
    std::uint32_t linearBuckets_;
    std::vector<std::uint64_t> buckets_;
    std::uint64_t count_ = 0;
    double sum_ = 0.0;  // weighted sum of values
    std::uint64_t min_ = 0, max_ = 0;
};

// A queue's occupancy over time: the histogram weight of a level is the
// number of cycles the queue held that many entries (the level at the end
// of each simulated cycle holds until the next change).
class OccupancyTracker {
public:
    explicit OccupancyTracker(std::uint32_t capacity = 0) : hist_(Histogram::Scheme::Linear, capacity + 1) {}

    void set(std::uint64_t level, std::uint64_t now) {
        if (level == level_) return;
        if (now > since_) hist_.add(level_, now - since_);
        since_ = now;
        level_ = level;
    }
    std::uint64_t level() const { return level_; }
    // Starts a new measurement at `now` (the level is kept).
    void reset(std::uint64_t now) {
        hist_.clear();
        since_ = now;
    }
    // The histogram including the current level up to `now`.
    Histogram histogram(std::uint64_t now) const {
        Histogram h = hist_;
        if (now > since_) h.add(level_, now - since_);
        return h;
    }
    nlohmann::json toJson(std::uint64_t now) const { return histogram(now).toJson(); }

private:
    Histogram hist_;
    std::uint64_t level_ = 0;
    std::uint64_t since_ = 0;
};

}  // namespace rtlab::rtcore_sim
