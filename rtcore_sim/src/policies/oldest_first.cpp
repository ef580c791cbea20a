// Oldest first: the ready ray submitted earliest issues first.
#include <rtlab/rtcore_sim/scheduler.hpp>

#include <queue>
#include <vector>

namespace rtlab::rtcore_sim {
namespace {

class OldestFirstPolicy final : public SchedulerPolicy {
public:
    void push(const ReadyRay& ray) override { heap_.push(ray); }
    bool pop(ReadyRay& out) override {
        if (heap_.empty()) return false;
        out = heap_.top();
        heap_.pop();
        return true;
    }
    bool usesAddress() const override { return false; }
    std::size_t size() const override { return heap_.size(); }

private:
    struct Younger {  // ages are unique: a strict order, so the choice is deterministic
        bool operator()(const ReadyRay& a, const ReadyRay& b) const { return a.age > b.age; }
    };
    std::priority_queue<ReadyRay, std::vector<ReadyRay>, Younger> heap_;
};

}  // namespace

const SchedulerPolicyEntry& rtcoreSimPolicy_oldest_first() {
    static const SchedulerPolicyEntry entry{"oldestFirst", "the ready ray submitted earliest issues first",
                                            [](const SchedulerParams&) -> std::unique_ptr<SchedulerPolicy> {
                                                return std::make_unique<OldestFirstPolicy>();
                                            }};
    return entry;
}

}  // namespace rtlab::rtcore_sim
