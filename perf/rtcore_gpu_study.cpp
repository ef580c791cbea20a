// The GPU-level study of docs/rtcore-model.md ("GPU study"): on the scalable
// workloads, 8 simulated cores with the L2 in mode cache, cycles and rays per
// cycle for each scheduling policy x L1 (cache.sizeBytes) x L2 (l2.sizeBytes),
// for several scene seeds. Rays: primary rays at W x H and one cosine-weighted
// diffuse bounce from every primary hit (rtcore_sim::diffuseBounceRays), one
// frame, batches of --batch rays, a cold GPU per point.
//
//   rtcore_gpu_study [--scene SRC]... [--seeds 0,1,2] [--width 128] [--height 96] [--batch 8192]
//                    [--policies fifo,oldestFirst,treelet] [--l1 16384,65536] [--l2 1048576,4194304]
//                    [--set section.field=value]...
//
// Prints one CSV line per point (scene, seed, policy, l1, l2, rays, cycles,
// raysPerCycle, l1HitRate, l2HitRate, dramBytesPerCycle, dramUtilization,
// meanLatency, latency shares of fetch / l2 / dram / inputQueue / scheduler,
// port utilization, prefetched lines and their accuracy).
// Deterministic: the same arguments print the same numbers.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/rtcore_sim/workloads.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <span>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace rtlab;
using namespace rtlab::rtcore_sim;

std::vector<std::string> split(const std::string& s) {
    std::vector<std::string> out;
    std::stringstream in(s);
    for (std::string item; std::getline(in, item, ',');)
        if (!item.empty()) out.push_back(item);
    return out;
}

struct Options {
    std::vector<std::string> scenes;
    std::vector<std::string> seeds{"0", "1", "2"};
    int width = 128, height = 96;
    std::size_t batch = 8192;
    std::vector<std::string> policies{"fifo", "oldestFirst", "treelet"};
    std::vector<std::string> l1{"16384", "65536"}, l2{"1048576", "4194304"};
    std::vector<std::string> sets;
};

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw InputError("rtcore_gpu_study", a + ": missing value");
            return argv[++i];
        };
        if (a == "--scene") o.scenes.push_back(value());
        else if (a == "--seeds") o.seeds = split(value());
        else if (a == "--width") o.width = std::stoi(value());
        else if (a == "--height") o.height = std::stoi(value());
        else if (a == "--batch") o.batch = std::stoul(value());
        else if (a == "--policies") o.policies = split(value());
        else if (a == "--l1") o.l1 = split(value());
        else if (a == "--l2") o.l2 = split(value());
        else if (a == "--set") o.sets.push_back(value());
        else throw InputError("rtcore_gpu_study", "unknown argument " + a);
    }
    if (o.scenes.empty())
        o.scenes = {"builtin:terrain?triangles=200000", "builtin:forest?instances=200",
                    "builtin:hairball?triangles=50000"};
    return o;
}

std::string withSeed(const std::string& source, const std::string& seed) {
    return source + (source.find('?') == std::string::npos ? "?" : "&") + "seed=" + seed;
}

int run(const Options& o) {
    std::printf(
        "scene,seed,policy,l1Bytes,l2Bytes,rays,cycles,raysPerCycle,l1HitRate,l2HitRate,dramBytesPerCycle,"
        "dramUtilization,meanLatency,shareFetch,shareL2,shareDram,shareInputQueue,shareScheduler,portUtilization,"
        "prefetchLines,prefetchAccuracy\n");
    for (const std::string& source : o.scenes)
        for (const std::string& seed : o.seeds) {
            const std::string src = withSeed(source, seed);
            ecs::World world;
            ecs::load::loadScene(world, src);
            const ecs::SceneSnapshot snapshot = ecs::makeSnapshot(world, world.update(0.f));
            RtCoreConfig base;
            base.gpu.cores = 8;
            base.l2.mode = L2Mode::Cache;
            for (const std::string& s : o.sets) base.set(s, "--set");
            ModelScene model(base.bvh);
            model.update(snapshot);
            // Step: the rays, primary then one diffuse bounce from every primary hit.
            const shaders::PinholeCamera camera(snapshot.camera, o.width, o.height);
            std::vector<SimRay> rays;
            for (int y = 0; y < o.height; ++y)
                for (int x = 0; x < o.width; ++x) {
                    const shaders::CameraRay r = camera.ray(x + 0.5f, y + 0.5f);
                    SimRay s;
                    s.ray.origin = r.origin;
                    s.ray.direction = r.direction;
                    rays.push_back(s);
                }
            std::vector<ModelHit> hits(rays.size());
            for (std::size_t i = 0; i < rays.size(); ++i) {
                TraversalCounters c;
                hits[i] = traceClosestHit(model, rays[i].ray, c);
            }
            const std::vector<SimRay> bounce = diffuseBounceRays(snapshot, rays, hits, 1, std::stoul(seed));
            rays.insert(rays.end(), bounce.begin(), bounce.end());

            for (const std::string& policy : o.policies)
                for (const std::string& l1 : o.l1)
                    for (const std::string& l2 : o.l2) {
                        RtCoreConfig config = base;
                        config.set("scheduler.policy=" + policy, "--policies");
                        config.set("cache.sizeBytes=" + l1, "--l1");
                        config.set("l2.sizeBytes=" + l2, "--l2");
                        config.validate("rtcore_gpu_study");
                        RtCore gpu(config, model);
                        std::vector<SimRayResult> results(rays.size());
                        OpaqueSide side;
                        for (std::size_t first = 0; first < rays.size(); first += o.batch) {
                            const std::size_t n = std::min(o.batch, rays.size() - first);
                            gpu.run(std::span(rays).subspan(first, n), side, std::span(results).subspan(first, n));
                        }
                        const nlohmann::json s = gpu.statsJson();
                        const nlohmann::json& b = s["rays"]["latencyBreakdown"];
                        const double total = s["rays"]["latency"]["mean"].get<double>() *
                                             std::max(1.0, s["rays"]["latency"]["count"].get<double>());
                        const auto share = [&](const char* k) { return total > 0 ? b[k].get<double>() / total : 0.0; };
                        const bool pf = s["cache"].contains("prefetch");
                        std::printf(
                            "%s,%s,%s,%s,%s,%zu,%llu,%.4f,%.4f,%.4f,%.2f,%.4f,%.1f,%.3f,%.3f,%.3f,%.3f,%.3f,%.4f,%llu,%"
                            ".4f\n",
                            source.c_str(), seed.c_str(), policy.c_str(), l1.c_str(), l2.c_str(), rays.size(),
                            static_cast<unsigned long long>(s["frame"]["cycles"].get<std::uint64_t>()),
                            s["frame"]["raysPerCycle"].get<double>(), s["cache"]["hitRate"].get<double>(),
                            s["l2"]["hitRate"].get<double>(), s["dram"]["bytesPerCycle"].get<double>(),
                            s["dram"]["utilization"].get<double>(), s["rays"]["latency"]["mean"].get<double>(),
                            share("fetch"), share("l2"), share("dram"), share("inputQueue"), share("scheduler"),
                            s["memory"]["utilization"].get<double>(),
                            static_cast<unsigned long long>(pf ? s["cache"]["prefetch"]["lines"].get<std::uint64_t>()
                                                               : 0),
                            pf ? s["cache"]["prefetch"]["accuracy"].get<double>() : 0.0);
                        std::fflush(stdout);
                    }
        }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        return run(parse(argc, argv));
    } catch (const InputError& e) {
        std::cerr << "rtcore_gpu_study: " << e.what() << "\n";
        return 2;
    } catch (const std::exception& e) {
        std::cerr << "rtcore_gpu_study: " << e.what() << "\n";
        return 1;
    }
}
