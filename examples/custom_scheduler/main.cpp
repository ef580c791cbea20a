// A ray-scheduling policy of your own for the RT-core model, registered at
// run time from outside the library (rtcore_sim::registerSchedulerPolicy):
// "nearestAddress" issues the ready ray whose next fetch is closest in memory
// to the previous issue, hoping for node-cache hits. The program renders the
// same frame with the built-in fifo policy and with it, prints cycles and
// cache hit rates, and checks that the images are identical (the policy may
// change timing, never results).
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/rtcore_sim/scheduler.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <string>

using namespace rtlab;
using namespace rtlab::rtcore_sim;

namespace {

// Ready rays ordered by the address of their next fetch; pop() takes the
// first at or after the last issued address, wrapping around (an elevator).
// Deterministic: ties are broken by age.
class NearestAddressPolicy final : public SchedulerPolicy {
public:
    void push(const ReadyRay& ray) override { ready_.emplace(Key{ray.address, ray.age}, ray); }
    bool pop(ReadyRay& out) override {
        if (ready_.empty()) return false;
        auto it = ready_.lower_bound(Key{last_, 0});
        if (it == ready_.end()) {
            it = ready_.begin();
            ++wraps_;
        }
        out = it->second;
        last_ = out.address;
        ready_.erase(it);
        return true;
    }
    std::size_t size() const override { return ready_.size(); }
    bool usesAddress() const override { return true; }
    void addStats(nlohmann::json& out) const override { out["nearestAddressWraps"] = wraps_; }
    void resetStats() override { wraps_ = 0; }

private:
    using Key = std::pair<std::uint64_t, std::uint64_t>;  // (address, age)
    std::map<Key, ReadyRay> ready_;
    std::uint64_t last_ = 0;
    std::uint64_t wraps_ = 0;
};

const SchedulerPolicyEntry& nearestAddressEntry() {
    static const SchedulerPolicyEntry entry{
        "nearestAddress", "the ready ray whose next fetch is nearest above the last one (elevator order)",
        [](const SchedulerParams&) -> std::unique_ptr<SchedulerPolicy> {
            return std::make_unique<NearestAddressPolicy>();
        }};
    return entry;
}

struct Result {
    shaders::PreviewResult preview;
    nlohmann::json stats;
};

Result renderWith(const std::string& policy, const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene) {
    RtCoreConfig config;
    config.set("scheduler.policy=" + policy);  // the same path as JSON files and --rtcore-set
    RtCoreBackend model(config);
    model.update(scene);
    model.beginFrame();
    shaders::PreviewSettings settings;
    settings.width = 128;
    settings.height = 96;
    settings.backend = &model;
    Result r{shaders::renderPreview(accel, scene, settings), {}};
    r.stats = model.statsJson();
    return r;
}

}  // namespace

int main() {
    registerSchedulerPolicy(nearestAddressEntry());

    ecs::World world;
    ecs::load::loadScene(world, "builtin:cornell");
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    tracer::AccelManager accel;
    accel.update(scene);

    const Result fifo = renderWith("fifo", accel, scene);
    const Result mine = renderWith("nearestAddress", accel, scene);
    for (const Result* r : {&fifo, &mine})
        std::printf("%-15s %10llu cycles, cache hit rate %.4f\n",
                    r->stats["scheduler"]["policy"].get<std::string>().c_str(),
                    (unsigned long long)r->stats["frame"]["cycles"].get<std::uint64_t>(),
                    r->stats["cache"]["hitRate"].get<double>());
    const bool identical = compareImages(mine.preview.image, fifo.preview.image).identical;
    std::printf("images identical: %s\n", identical ? "true" : "false");
    if (!identical || mine.stats["scheduler"]["policy"] != "nearestAddress" || mine.preview.hits == 0) {
        std::fprintf(stderr, "custom_scheduler: the registered policy was not used or changed the image\n");
        return 1;
    }
    return 0;
}
