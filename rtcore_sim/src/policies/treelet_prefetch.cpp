// Treelet prefetching after Chou, Nowicki, Aamodt et al. 2023 ("Treelet
// Prefetching For Ray Tracing", MICRO 2023): the BVH is cut into treelets and,
// when a ray's traversal enters a treelet, the RT unit prefetches that
// treelet's nodes into its cache so that the ray's next steps there hit.
//
// Here a treelet is, as for the treelet policy, the aligned block of
// scheduler.treeletBytes bytes holding a step's node, leaf or instance (the
// depth-first node order makes such blocks subtrees). Rays issue in FIFO
// order (so that the prefetcher is the only difference to fifo). When a ray
// becomes ready and its next step lies in another treelet than its previous
// step (or it is the ray's first step), the policy asks the core to
// prefetch scheduler.prefetchBytes bytes from that step's address, clipped to
// the end of the treelet: the entered subtree's first nodes, which the
// depth-first layout places after its root. The core reads the lines not in
// its node cache through its memory port (and the L2) without any ray
// waiting for them (NodeCache::prefetch); cache.prefetch counts requests,
// lines read and lines later hit by demand (usefulLines).
#include <rtlab/rtcore_sim/scheduler.hpp>

#include <algorithm>
#include <deque>
#include <vector>

namespace rtlab::rtcore_sim {
namespace {

class TreeletPrefetchPolicy final : public SchedulerPolicy {
public:
    explicit TreeletPrefetchPolicy(const SchedulerParams& params)
        : treeletBytes_(params.treeletBytes), prefetchBytes_(params.prefetchBytes) {}

    void push(const ReadyRay& ray) override {
        queue_.push_back(ray);
        if (ray.slot >= last_.size()) last_.resize(ray.slot + 1);
        Last& last = last_[ray.slot];
        const std::uint64_t treelet = ray.address / treeletBytes_;
        if (!last.valid || last.age != ray.age || last.treelet != treelet) {
            const std::uint64_t end = (treelet + 1) * treeletBytes_;
            const std::uint64_t bytes = std::min<std::uint64_t>(prefetchBytes_, end - ray.address);
            prefetches_.push_back(PrefetchRequest{ray.address, static_cast<std::uint32_t>(bytes)});
            ++entries_;
        }
        last = Last{true, ray.age, treelet};
    }
    bool pop(ReadyRay& out) override {
        if (queue_.empty()) return false;
        out = queue_.front();
        queue_.pop_front();
        return true;
    }
    bool takePrefetch(PrefetchRequest& out) override {
        if (prefetches_.empty()) return false;
        out = prefetches_.front();
        prefetches_.pop_front();
        return true;
    }
    std::size_t size() const override { return queue_.size(); }
    void addStats(nlohmann::json& out) const override {
        out["treeletEntries"] = entries_;
        out["treeletBytes"] = treeletBytes_;
    }
    void resetStats() override { entries_ = 0; }

private:
    struct Last {
        bool valid = false;
        std::uint64_t age = 0;
        std::uint64_t treelet = 0;
    };
    std::uint64_t treeletBytes_;
    std::uint32_t prefetchBytes_;
    std::deque<ReadyRay> queue_;
    std::deque<PrefetchRequest> prefetches_;
    std::vector<Last> last_;  // per ray slot: the treelet of the ray's previous step
    std::uint64_t entries_ = 0;
};

}  // namespace

const SchedulerPolicyEntry& rtcoreSimPolicy_treelet_prefetch() {
    static const SchedulerPolicyEntry entry{
        "treeletPrefetch",
        "fifo issue + treelet prefetch into the node cache when a ray enters a treelet (Chou et al. 2023)",
        [](const SchedulerParams& params) -> std::unique_ptr<SchedulerPolicy> {
            return std::make_unique<TreeletPrefetchPolicy>(params);
        }};
    return entry;
}

}  // namespace rtlab::rtcore_sim
