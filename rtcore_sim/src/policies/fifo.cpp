// In-order FIFO: rays issue in the order they became ready.
#include <rtlab/core/ring_queue.hpp>
#include <rtlab/rtcore_sim/scheduler.hpp>

namespace rtlab::rtcore_sim {
namespace {

class FifoPolicy final : public SchedulerPolicy {
public:
    void push(const ReadyRay& ray) override { queue_.push_back(ray); }
    bool pop(ReadyRay& out) override {
        if (queue_.empty()) return false;
        out = queue_.front();
        queue_.pop_front();
        return true;
    }
    bool usesAddress() const override { return false; }
    std::size_t size() const override { return queue_.size(); }

private:
    RingQueue<ReadyRay> queue_;
};

}  // namespace

const SchedulerPolicyEntry& rtcoreSimPolicy_fifo() {
    static const SchedulerPolicyEntry entry{
        "fifo", "rays issue in the order they became ready",
        [](const SchedulerParams&) -> std::unique_ptr<SchedulerPolicy> { return std::make_unique<FifoPolicy>(); }};
    return entry;
}

}  // namespace rtlab::rtcore_sim
