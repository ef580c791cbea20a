#pragma once
// RtCore::Impl, the GPU level of the timing model: cores in lock step on one clock, warp dispatch, host-parallel
// epochs, the shared L2 and DRAM (docs/rtcore-model.md, "GPU level"). Its methods are in gpu_level.cpp, its
// statsJson in stats_tree.cpp.
#include <rtlab/rtcore_sim/cache.hpp>
#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>

#include "core_cycle.hpp"

#include <nlohmann/json.hpp>
#include <tbb/partitioner.h>

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace rtlab::rtcore_sim {

// ---------------------------------------------------------------------------
// The GPU: cores in lock step on one clock, the shared L2 and DRAM.

struct RtCore::Impl {
    RtCoreConfig config;
    const ModelScene& scene;
    MemoryLayout layout;
    std::uint64_t layoutGeneration = ~std::uint64_t(0);
    BatchState batch;
    std::unique_ptr<SharedL2> l2;  // l2 mode cache only
    std::vector<std::unique_ptr<Core>> cores;
    std::vector<std::size_t> cursor;  // scratch: per core, a position in its log (mergeByCycle)
    struct alignas(64) L2Group {      // one host thread's share of answering L2 reads (answerL2Reads)
        L2Counters counters;
        std::uint64_t stamp = 0;
        std::vector<std::uint64_t> ready;  // per core: the earliest answer to its reads
        struct Key {
            std::uint64_t cycle;
            std::uint32_t core, position;
            bool operator<(const Key& o) const {
                return cycle != o.cycle ? cycle < o.cycle : core != o.core ? core < o.core : position < o.position;
            }
        };
        std::vector<Key> order;  // scratch: one class's reads in the serial order
    };
    std::vector<L2Group> l2Groups;
    // Host-parallel epochs: which host thread ran which core, replayed in the
    // next epoch where the load allows, so a core's state stays in that
    // thread's cache (tbb::affinity_partitioner).
    tbb::affinity_partitioner coreAffinity, l2Affinity;
    bool everyCycle = false;  // debug: visit every cycle instead of jumping to the next event
    std::uint64_t now = 0;    // the clock between batches
    std::uint64_t clock = 0;  // the cycle being simulated during a batch
    std::uint64_t frameStart = 0, batches = 0;

    Impl(const RtCoreConfig& cfg, const ModelScene& s);

    void dispatch(std::uint32_t warpCount);
    void tileGroups(std::uint32_t warps);
    void launchGroups(std::span<const std::uint32_t> threads, std::uint32_t threadCount);
    void checkRays(std::span<const SimRay> rays, std::size_t results, const char* what);
    template <class MakeGroups>
    void simulateBatch(std::span<const SimRay> rays, ProgrammableSide& programmable, std::span<SimRayResult> out,
                       std::uint32_t warps, MakeGroups&& makeGroups);
    static unsigned hostThreads();
    template <class CycleOf, class SizeOf, class Visitor>
    void mergeByCycle(std::vector<std::size_t>& cursor, const CycleOf& cycleOf, const SizeOf& sizeOf,
                      Visitor&& visitor) const;
    void simulate(bool parallel);
    void answerL2Reads(std::size_t threads);
    [[noreturn]] void rethrowFirstError();
    void mergeRayTypes();
    std::uint64_t portsFree(std::uint64_t c) const;

    void run(std::span<const SimRay> rays, ProgrammableSide& programmable, std::span<SimRayResult> out);
    void runLaunch(std::span<const SimRay> rays, std::span<const std::uint32_t> threads, std::uint32_t threadCount,
                   ProgrammableSide& programmable, std::span<SimRayResult> out);
    void abortBatch();
    void resetStats();
    void reset();

    nlohmann::json statsJson() const;
};

}  // namespace rtlab::rtcore_sim
