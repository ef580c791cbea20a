// Treelet queues after Aila & Karras 2010 ("Architecture considerations for
// tracing incoherent rays"): ready rays wait in one queue per treelet, the
// treelet being the aligned block of scheduler.treeletBytes bytes holding
// the node, leaf or instance the ray fetches next. The scheduler drains one
// treelet at a time, so consecutive fetches fall into the same few cache
// lines: it picks the treelet with the most waiting rays (ties: the lowest
// treelet address) and issues the rays queued there at that moment (FIFO),
// then picks again.
#include <rtlab/rtcore_sim/scheduler.hpp>

#include <deque>
#include <unordered_map>
#include <vector>

namespace rtlab::rtcore_sim {
namespace {

class TreeletPolicy final : public SchedulerPolicy {
public:
    explicit TreeletPolicy(const SchedulerParams& params) : treeletBytes_(params.treeletBytes) {}

    void push(const ReadyRay& ray) override {
        const std::uint64_t key = ray.address / treeletBytes_;
        // The map is only looked up, never iterated: choices do not depend on hashing.
        auto [it, inserted] = queueOf_.try_emplace(key, 0u);
        if (inserted) {
            it->second = allocateQueue(key);
            nonEmpty_.push_back(it->second);
        }
        queues_[it->second].rays.push_back(ray);
        ++size_;
    }

    bool pop(ReadyRay& out) override {
        if (size_ == 0) return false;
        if (current_ == kNone || burst_ == 0 || queues_[current_].rays.empty()) choose();
        Queue& q = queues_[current_];
        out = q.rays.front();
        q.rays.pop_front();
        --burst_;
        --size_;
        if (q.rays.empty()) release(current_);
        return true;
    }

    std::size_t size() const override { return size_; }
    void addStats(nlohmann::json& out) const override {
        out["treeletSwitches"] = switches_;
        out["treeletBytes"] = treeletBytes_;
    }
    void resetStats() override { switches_ = 0; }

private:
    static constexpr std::uint32_t kNone = ~0u;
    struct Queue {
        std::uint64_t key = 0;
        std::deque<ReadyRay> rays;
    };

    std::uint32_t allocateQueue(std::uint64_t key) {
        std::uint32_t index;
        if (!free_.empty()) {
            index = free_.back();
            free_.pop_back();
        } else {
            index = static_cast<std::uint32_t>(queues_.size());
            queues_.emplace_back();
        }
        queues_[index].key = key;
        return index;
    }
    void release(std::uint32_t index) {
        queueOf_.erase(queues_[index].key);
        for (std::size_t i = 0; i < nonEmpty_.size(); ++i)
            if (nonEmpty_[i] == index) {
                nonEmpty_[i] = nonEmpty_.back();
                nonEmpty_.pop_back();
                break;
            }
        free_.push_back(index);
        if (current_ == index) current_ = kNone;
    }
    // The treelet with the most waiting rays, ties to the lowest address.
    void choose() {
        std::uint32_t best = kNone;
        for (std::uint32_t index : nonEmpty_) {
            const Queue& q = queues_[index];
            if (best == kNone || q.rays.size() > queues_[best].rays.size() ||
                (q.rays.size() == queues_[best].rays.size() && q.key < queues_[best].key))
                best = index;
        }
        if (best != current_) ++switches_;
        current_ = best;
        burst_ = queues_[best].rays.size();
    }

    std::uint64_t treeletBytes_;
    std::unordered_map<std::uint64_t, std::uint32_t> queueOf_;
    std::vector<Queue> queues_;
    std::vector<std::uint32_t> nonEmpty_;  // queues holding rays (order irrelevant to the choice)
    std::vector<std::uint32_t> free_;
    std::uint32_t current_ = kNone;
    std::size_t burst_ = 0;  // rays still to issue from the current treelet before choosing again
    std::size_t size_ = 0;
    std::uint64_t switches_ = 0;
};

}  // namespace

const SchedulerPolicyEntry& rtcoreSimPolicy_treelet() {
    static const SchedulerPolicyEntry entry{
        "treelet", "treelet queues (Aila & Karras 2010): drain the treelet with the most waiting rays",
        [](const SchedulerParams& params) -> std::unique_ptr<SchedulerPolicy> {
            return std::make_unique<TreeletPolicy>(params);
        }};
    return entry;
}

}  // namespace rtlab::rtcore_sim
