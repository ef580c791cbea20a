// Host speed of the timing model: simulated rays per host-second on one
// thread for showcase primary rays plus one diffuse bounce per hit, next to
// the functional traversal and Embree's rtcIntersect1 on the same rays.
// Prints the numbers (the acceptance benchmark lives in perf/); asserts only
// that all three agree on the hits.
#include "rtcore_timing_helpers.hpp"

#include <rtlab/rtcore_sim/workloads.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <gtest/gtest.h>

#include <embree3/rtcore.h>

#include <chrono>
#include <iostream>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using namespace rtlab::rtcore_sim::test_support;

namespace {

double seconds(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
}

}  // namespace

TEST(RtCoreSpeed, ShowcasePrimaryAndDiffuseRaysPerHostSecond) {
    const RtCoreConfig config;
    MicroScene scene;
    loadScene(scene, "builtin:showcase", config.bvh);
    std::vector<SimRay> rays = primaryRays(scene.snapshot.camera, 320, 240, 0);
    std::vector<ModelHit> primaryHits(rays.size());
    for (std::size_t i = 0; i < rays.size(); ++i) {
        TraversalCounters c;
        primaryHits[i] = traceClosestHit(*scene.model, rays[i].ray, c);
    }
    const std::vector<SimRay> bounces = diffuseBounceRays(scene.snapshot, rays, primaryHits);
    rays.insert(rays.end(), bounces.begin(), bounces.end());

    // Functional traversal.
    std::vector<ModelHit> functional(rays.size());
    auto t0 = std::chrono::steady_clock::now();
    for (std::size_t i = 0; i < rays.size(); ++i) {
        TraversalCounters c;
        functional[i] = traceClosestHit(*scene.model, rays[i].ray, c);
    }
    auto t1 = std::chrono::steady_clock::now();
    const double functionalRate = double(rays.size()) / seconds(t0, t1);

    // Timing model: batches of 1024 rays (a frame of several batches).
    RtCore core(config, *scene.model);
    std::vector<SimRayResult> results(rays.size());
    OpaqueSide side;
    t0 = std::chrono::steady_clock::now();
    for (std::size_t first = 0; first < rays.size(); first += 1024) {
        const std::size_t n = std::min<std::size_t>(1024, rays.size() - first);
        core.run(std::span(rays).subspan(first, n), side, std::span(results).subspan(first, n));
    }
    t1 = std::chrono::steady_clock::now();
    const double simulatedRate = double(rays.size()) / seconds(t0, t1);

    // Embree, single rays.
    tracer::AccelManager accel;
    accel.update(scene.snapshot);
    std::uint64_t embreeHits = 0;
    t0 = std::chrono::steady_clock::now();
    for (const SimRay& r : rays) {
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        RTCRayHit rh{};
        rh.ray.org_x = r.ray.origin.x;
        rh.ray.org_y = r.ray.origin.y;
        rh.ray.org_z = r.ray.origin.z;
        rh.ray.dir_x = r.ray.direction.x;
        rh.ray.dir_y = r.ray.direction.y;
        rh.ray.dir_z = r.ray.direction.z;
        rh.ray.tnear = r.ray.tMin;
        rh.ray.tfar = r.ray.tMax;
        rh.ray.mask = 0xff;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(accel.tlas(), &ctx, &rh);
        embreeHits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
    }
    t1 = std::chrono::steady_clock::now();
    const double embreeRate = double(rays.size()) / seconds(t0, t1);

    std::uint64_t same = 0, modelHits = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
        same += sameHit(results[i].hit, functional[i]);
        modelHits += results[i].hit.hit;
    }
    EXPECT_EQ(same, rays.size());
    const auto stats = core.statsJson();
    std::cout << "[ rtcore   ] showcase 320x240 primary + diffuse bounce: " << rays.size() << " rays ("
              << bounces.size() << " bounces), model hits " << modelHits << ", Embree hits " << embreeHits << "\n"
              << "[ rtcore   ] host rays/s on one thread: timing model " << simulatedRate << ", functional "
              << functionalRate << ", Embree rtcIntersect1 " << embreeRate
              << " (timing model / Embree = " << simulatedRate / embreeRate << ")\n"
              << "[ rtcore   ] simulated: " << stats["frame"]["cycles"] << " cycles, " << stats["frame"]["raysPerCycle"]
              << " rays/cycle, cache hit rate " << stats["cache"]["hitRate"] << ", box unit utilization "
              << stats["traversalUnits"]["utilization"] << ", mean latency " << stats["rays"]["latency"]["mean"]
              << " cycles\n";
}
