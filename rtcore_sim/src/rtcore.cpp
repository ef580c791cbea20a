// The event-driven timing model of the RT cores of a GPU (docs/rtcore-model.md,
// "Timing model", "GPU level"). The cores share one clock; every simulated
// cycle runs, for each core in index order, five phases in this order:
//   1. events due this cycle (fetch done -> unit, stack traffic, step done)
//   2. completion: up to completionPerCycle results leave the completion
//      queue; blocked finished rays move into the freed entries
//   3. submission: the next warp enters the input queue if it fits whole
//   4. admission: up to admitPerCycle rays move from the input queue into
//      free ray slots (and are ready at once)
//   5. issue: the scheduler issues up to issueWidth ready rays' next steps
// Cycles in which no core can do anything in phases 2-5 are skipped: the
// clock jumps to the next event of any core. Misses of a core's node cache go
// through its memory port and, in l2 mode cache, to the shared L2 and DRAM.
// With a side that allows concurrent callbacks the cores run in host-parallel
// epochs instead (simulate): same cycles and statistics, several threads.
// RtCore itself (this file) checks its configuration and forwards to the GPU level: gpu_level.cpp (dispatch,
// lock step, epochs), core_cycle.cpp (one core's cycle), event_queue.hpp and unit_pool.hpp (its timing
// primitives), stats_tree.cpp (statsJson).
#include <rtlab/rtcore_sim/rtcore.hpp>

#include "gpu_level.hpp"

#include <memory>
#include <stdexcept>

namespace rtlab::rtcore_sim {
namespace {

void checkBvhParams(const RtCoreConfig& config, const ModelScene& scene) {
    for (const auto& f : bvhParamTable().fields())
        if (f.read(config.bvh) != f.read(scene.params()))
            throw std::invalid_argument("RtCore: the ModelScene was built with bvh." + f.info.name + " = " +
                                        f.read(scene.params()).dump() + ", the configuration says " +
                                        f.read(config.bvh).dump() + " (build the scene with config.bvh)");
}

}  // namespace

RtCore::RtCore(const RtCoreConfig& config, const ModelScene& scene) {
    config.validate("RT-core configuration");
    checkBvhParams(config, scene);
    impl_ = std::make_unique<Impl>(config, scene);
}

RtCore::~RtCore() = default;

void RtCore::run(std::span<const SimRay> rays, ProgrammableSide& side, std::span<SimRayResult> results) {
    impl_->run(rays, side, results);
}

void RtCore::runLaunch(std::span<const SimRay> rays, std::span<const std::uint32_t> threads, std::uint32_t threadCount,
                       ProgrammableSide& side, std::span<SimRayResult> results) {
    impl_->runLaunch(rays, threads, threadCount, side, results);
}

nlohmann::json RtCore::statsJson() const { return impl_->statsJson(); }
void RtCore::resetStats() { impl_->resetStats(); }
void RtCore::reset() { impl_->reset(); }
std::uint64_t RtCore::cycle() const { return impl_->now; }

std::vector<ResourceUse> RtCore::resourceUse() const {
    const RtCoreConfig& c = impl_->config;
    std::vector<ResourceUse> out;
    for (std::uint32_t k = 0; k < impl_->cores.size(); ++k) {
        const Core& core = *impl_->cores[k];
        const Histogram slots = core.slotOcc.histogram(impl_->now);
        out.push_back({"traversalUnits", k, double(core.boxUnits.busyCycles), double(c.traversal.units)});
        out.push_back({"triangleUnits", k, double(core.triangleUnits.busyCycles), double(c.triangle.units)});
        out.push_back({"transformUnits", k, double(core.transformUnits.busyCycles), double(c.transform.units)});
        out.push_back({"scheduler", k, double(core.stats.issued), double(c.scheduler.issueWidth)});
        out.push_back({"raySlots", k, slots.mean() * double(slots.count()), double(c.core.raySlots)});
        out.push_back({"memoryPort", k, double(core.port.channel.busyCycles), 1.0});
    }
    if (impl_->l2) {
        for (std::uint32_t b = 0; b < impl_->l2->banks(); ++b)
            out.push_back({"l2Bank", b, double(impl_->l2->bankBusyCycles(b)), 1.0});
        for (std::uint32_t ch = 0; ch < impl_->l2->channels(); ++ch)
            out.push_back({"dramChannel", ch, double(impl_->l2->channelBusyCycles(ch)), 1.0});
    }
    return out;
}
void RtCore::simulateEveryCycle(bool on) { impl_->everyCycle = on; }
const RtCoreConfig& RtCore::config() const { return impl_->config; }

}  // namespace rtlab::rtcore_sim
