#pragma once
// The laws every stats tree of the timing model obeys (rays in = rays out,
// utilizations <= 1, throughput bounds, queue capacities, Little's law, the
// latency breakdown adding up): checked on batches and on launches.
#include <rtlab/rtcore_sim/config.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace rtlab::rtcore_sim::test_support {

inline void expectInvariants(const nlohmann::json& s, const RtCoreConfig& config) {
    const double cycles = s["frame"]["cycles"].get<double>();
    ASSERT_GT(cycles, 0.0);
    const double coreCycles = cycles * config.gpu.cores;
    // Rays in = rays out.
    EXPECT_EQ(s["rays"]["submitted"], s["rays"]["completed"]);
    EXPECT_EQ(s["rays"]["latency"]["count"], s["rays"]["completed"]);
    // Every unit's work fits in the cycles: cycles >= busy / units.
    for (const char* unit : {"traversalUnits", "triangleUnits", "transformUnits"}) {
        const double busy = s[unit]["busyCycles"].get<double>(), units = s[unit]["units"].get<double>();
        EXPECT_GE(cycles, busy / units) << unit;
        const double u = s[unit]["utilization"].get<double>();
        EXPECT_GE(u, 0.0) << unit;
        EXPECT_LE(u, 1.0) << unit;
    }
    // Throughput bounds: boxes, tests, issues, memory bytes.
    EXPECT_GE(cycles, s["traversalUnits"]["boxTests"].get<double>() /
                          (config.traversal.units * config.traversal.boxesPerCycle));
    EXPECT_GE(cycles, (s["triangleUnits"]["triangleTests"].get<double>() +
                       s["triangleUnits"]["proceduralTests"].get<double>()) /
                          (config.triangle.units * config.triangle.testsPerCycle));
    EXPECT_GE(cycles, s["scheduler"]["issued"].get<double>() / config.scheduler.issueWidth);
    EXPECT_GE(cycles, (s["memory"]["readBytes"].get<double>() + s["memory"]["writeBytes"].get<double>()) /
                          config.memory.bytesPerCycle);
    for (const char* rate : {"utilization"}) {
        for (const char* unit : {"scheduler", "memory"}) {
            EXPECT_GE(s[unit][rate].get<double>(), 0.0) << unit;
            EXPECT_LE(s[unit][rate].get<double>(), 1.0) << unit;
        }
    }
    EXPECT_LE(s["raySlots"]["utilization"].get<double>(), 1.0);
    EXPECT_LE(s["cache"]["hitRate"].get<double>(), 1.0);
    EXPECT_EQ(s["cache"]["accesses"],
              s["cache"]["hits"].get<std::uint64_t>() + s["cache"]["misses"].get<std::uint64_t>());
    EXPECT_LE(s["simd"]["efficiency"].get<double>(), 1.0);
    EXPECT_GT(s["simd"]["efficiency"].get<double>(), 0.0);
    // Queue occupancies stay within capacity; their histograms cover every cycle.
    EXPECT_LE(s["submission"]["inputQueue"]["occupancy"]["max"].get<double>(), config.core.inputQueueRays);
    EXPECT_LE(s["completion"]["occupancy"]["max"].get<double>(), config.core.completionQueueRays);
    EXPECT_LE(s["raySlots"]["occupancy"]["max"].get<double>(), config.core.raySlots);
    EXPECT_EQ(s["raySlots"]["occupancy"]["count"].get<double>(), coreCycles);
    EXPECT_EQ(s["scheduler"]["readyRays"]["count"].get<double>(), coreCycles);
    // The latency breakdown adds up to the rays' latencies.
    std::uint64_t parts = 0;
    for (const auto& [name, value] : s["rays"]["latencyBreakdown"].items()) parts += value.get<std::uint64_t>();
    EXPECT_EQ(double(parts), s["rays"]["latency"]["mean"].get<double>() * s["rays"]["latency"]["count"].get<double>());
    // Per ray type: counts add up, active cycles within the frame.
    std::uint64_t typed = 0;
    for (const auto& [type, t] : s["rayTypes"].items()) {
        typed += t["rays"].get<std::uint64_t>();
        EXPECT_LE(t["activeCycles"].get<double>(), cycles) << type;
    }
    EXPECT_EQ(typed, s["rays"]["completed"].get<std::uint64_t>());
    // Little's law for the queues of each core: the time-mean occupancy
    // (over core-cycles) times the core-cycles is the sum of the rays' waits in the queue.
    // (The L2 banks and DRAM channels are reservations computed when a step
    // issues, not queues with an occupancy: their law is busy <= capacity x cycles.)
    const nlohmann::json& breakdown = s["rays"]["latencyBreakdown"];
    const double latencySum = s["rays"]["latency"]["mean"].get<double>() * s["rays"]["latency"]["count"].get<double>();
    // A ray holds a slot from admission until it enters the completion queue.
    const double slotResidence =
        latencySum - breakdown["inputQueue"].get<double>() - breakdown["completionQueue"].get<double>();
    EXPECT_NEAR(s["raySlots"]["occupancy"]["mean"].get<double>() * coreCycles, slotResidence,
                1e-6 * coreCycles + 1e-9 * slotResidence)
        << "ray slots";
    // A step waits among the ready rays from ready to issue.
    EXPECT_NEAR(s["scheduler"]["readyRays"]["mean"].get<double>() * coreCycles, breakdown["scheduler"].get<double>(),
                1e-6 * coreCycles + 1e-9 * breakdown["scheduler"].get<double>())
        << "ready rays";
    EXPECT_NEAR(s["submission"]["inputQueue"]["occupancy"]["mean"].get<double>() * coreCycles,
                s["rays"]["latencyBreakdown"]["inputQueue"].get<double>(),
                1e-6 * coreCycles + 1e-9 * s["rays"]["latencyBreakdown"]["inputQueue"].get<double>());
    EXPECT_NEAR(s["completion"]["occupancy"]["mean"].get<double>() * coreCycles,
                s["rays"]["latencyBreakdown"]["completionQueue"].get<double>(),
                1e-6 * coreCycles + 1e-9 * s["rays"]["latencyBreakdown"]["completionQueue"].get<double>());
    // The resolved configuration is echoed.
    EXPECT_EQ(s["config"], config.toJson());
}

}  // namespace rtlab::rtcore_sim::test_support
