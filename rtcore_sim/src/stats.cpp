#include <rtlab/rtcore_sim/stats.hpp>

#include <algorithm>
#include <bit>

namespace rtlab::rtcore_sim {

Histogram::Histogram(Scheme scheme, std::uint32_t linearBuckets)
    : scheme_(scheme), linearBuckets_(scheme == Scheme::Linear ? std::max<std::uint32_t>(linearBuckets, 1) : 0),
      buckets_(scheme == Scheme::Linear ? linearBuckets_ + 1 : 65, 0) {}

void Histogram::add(std::uint64_t value, std::uint64_t weight) {
    if (weight == 0) return;
    std::size_t bucket = 0;
    if (scheme_ == Scheme::Linear) bucket = std::min<std::uint64_t>(value, linearBuckets_);
    else bucket = value == 0 ? 0 : static_cast<std::size_t>(std::bit_width(value));
    buckets_[bucket] += weight;
    if (count_ == 0) {
        min_ = max_ = value;
    } else {
        min_ = std::min(min_, value);
        max_ = std::max(max_, value);
    }
    count_ += weight;
    sum_ += double(value) * double(weight);
}

void Histogram::merge(const Histogram& other) {
    if (other.count_ == 0) return;
    for (std::size_t b = 0; b < buckets_.size() && b < other.buckets_.size(); ++b) buckets_[b] += other.buckets_[b];
    if (count_ == 0) {
        min_ = other.min_;
        max_ = other.max_;
    } else {
        min_ = std::min(min_, other.min_);
        max_ = std::max(max_, other.max_);
    }
    count_ += other.count_;
    sum_ += other.sum_;
}

void Histogram::clear() {
    std::fill(buckets_.begin(), buckets_.end(), 0);
    count_ = 0;
    sum_ = 0.0;
    min_ = max_ = 0;
}

nlohmann::json Histogram::toJson() const {
    nlohmann::json out;
    out["count"] = count_;
    out["mean"] = mean();
    out["min"] = min();
    out["max"] = max();
    out["scheme"] = scheme_ == Scheme::Linear ? "linear" : "log2";
    nlohmann::json buckets = nlohmann::json::array();
    for (std::size_t b = 0; b < buckets_.size(); ++b) {
        if (buckets_[b] == 0) continue;
        std::uint64_t lo = 0, hi = 0;
        if (scheme_ == Scheme::Linear) {
            lo = b;
            hi = b < linearBuckets_ ? b + 1 : max_ + 1;  // the overflow bucket ends after the largest value
        } else {
            lo = b == 0 ? 0 : std::uint64_t(1) << (b - 1);
            hi = b == 0 ? 1 : (b >= 64 ? ~std::uint64_t(0) : std::uint64_t(1) << b);
        }
        buckets.push_back({lo, hi, buckets_[b]});
    }
    out["buckets"] = std::move(buckets);
    return out;
}

}  // namespace rtlab::rtcore_sim
