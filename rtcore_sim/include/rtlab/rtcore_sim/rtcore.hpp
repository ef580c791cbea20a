#pragma once
// The cycle-counted RT core (docs/rtcore-model.md, "Timing model"):
//
//   shader side --warps--> input queue --> ray slots --scheduler--> units --> completion queue --> shader side
//
// Rays are submitted in warps, wait in a bounded input queue, are admitted
// into ray slots, and traverse step by step (RayTraversal::step, the same
// step the functional traversal runs): each step fetches its node, leaf or
// instance through the node cache, then uses a box-test, primitive or
// instance-transform unit, round trips to the programmable side for shaders,
// and spills/refills its short stack. Finished rays leave through a bounded
// completion queue. Simulation is event driven (no cycle-by-cycle sweep over
// rays) and deterministic: the same inputs give the same cycles and stats.
//
// An RtCore object is the whole GPU (docs/rtcore-model.md, "GPU level"):
// gpu.cores such cores on one clock, each with its own node cache (L1) and
// memory port, sharing the L2 and DRAM (l2.mode = cache). Warps of a batch go
// to cores by gpu.dispatch. One core with the ideal L2 (the defaults) is the
// single-core model, cycle for cycle. Several cores run on the process's
// host threads (TBB) in lock-step epochs when the side allows concurrent
// callbacks (ProgrammableSide::concurrent), otherwise on the calling thread;
// cycles and stats are the same for any number of threads
// (docs/rtcore-model.md, "Host threads").
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace rtlab::rtcore_sim {

struct SimRayResult {
    ModelHit hit;
    std::uint32_t cycles = 0;      // submission (warp enters the input queue) -> completion (result returned)
    std::uint32_t slotCycles = 0;  // admission into a ray slot -> traversal finished (no queue waits)
    TraversalCounters work;
    std::uint32_t stackSpills = 0;   // entries this ray spilled from its short stack
    std::uint32_t stackRefills = 0;  // refills (memory reads) it needed
};

// One resource's work so far (RtCore::resourceUse): over an interval of C
// cycles its utilization is (busy after - busy before) / (capacity x C).
struct ResourceUse {
    std::string
        kind;  // traversalUnits, triangleUnits, transformUnits, scheduler, raySlots, memoryPort, l2Bank, dramChannel
    std::uint32_t index = 0;  // the core, bank or channel
    double busy = 0.0;        // busy unit-cycles (issued steps, occupied slot-cycles)
    double capacity = 1.0;    // units of it working at once
};

// At most this many threads in one launch (2^26: an 8192 x 8192 dispatch).
inline constexpr std::uint32_t kMaxLaunchThreads = 1u << 26;

class RtCore {
public:
    // `scene` must outlive the core and be built with config.bvh (checked:
    // std::invalid_argument otherwise). Cross-field rules of the config are
    // checked (RtCoreConfig::validate, InputError).
    RtCore(const RtCoreConfig& config, const ModelScene& scene);
    ~RtCore();
    RtCore(const RtCore&) = delete;
    RtCore& operator=(const RtCore&) = delete;

    // Simulates one batch, submitted in order as warps of config.core.warpWidth;
    // continues the core's clock (a frame is several batches) and returns when
    // every result is back. Fills results[i] for rays[i] (sizes must match).
    // Side callbacks receive the index into `rays`. A scene update since the
    // last batch (ModelScene::generation) relays out memory and invalidates
    // the node cache. If a side callback throws, the batch's rays are
    // dropped, the exception propagates, and the core stays usable (its
    // clock at the cycle reached).
    void run(std::span<const SimRay> rays, ProgrammableSide& side, std::span<SimRayResult> results);

    // Simulates one launch (docs/rtcore-model.md, "Launches"): rays[i] was
    // traced by thread threads[i] < threadCount; a thread's rays are in the
    // order it traced them. Warps are threadCount / core.warpWidth runs of
    // consecutive threads, dispatched to cores by gpu.dispatch, at most
    // gpu.residentWarps resident per core; a warp submits its threads' k-th
    // rays together, shader.nextTraceLatency cycles after its (k-1)-th rays'
    // last result. Side callbacks receive the index into `rays`. Continues
    // the clock like run(); gpu.launch is not read (the caller chose).
    // `results` is one per ray, or empty when the caller needs no per-ray
    // results (a launch of millions of rays then writes none; the
    // statistics are the same).
    // InputError when gpu.rayOrder is not submission or threadCount > kMaxLaunchThreads.
    void runLaunch(std::span<const SimRay> rays, std::span<const std::uint32_t> threads, std::uint32_t threadCount,
                   ProgrammableSide& side, std::span<SimRayResult> results);

    // The stats tree, with "config" = the resolved configuration; derived
    // rates are computed here. Top level = all cores; "cores" = one tree per
    // core; "l2", "dram" = the shared memory.
    nlohmann::json statsJson() const;
    // Start of a frame: zeroes the statistics (the clock and the cache stay).
    void resetStats();
    // Cold start: clock 0, empty cache and memory channel, statistics zeroed.
    void reset();
    std::uint64_t cycle() const;
    // Every resource of every core, then every L2 bank and DRAM channel (l2
    // mode cache), with its busy work since the last resetStats.
    std::vector<ResourceUse> resourceUse() const;
    const RtCoreConfig& config() const;
    // Debug aid: visit every cycle instead of jumping over cycles in which
    // nothing can happen. Results and statistics must not change (tested).
    void simulateEveryCycle(bool on);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace rtlab::rtcore_sim
