#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/timer.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>

namespace rtlab::app {

void addRenderCommand(CLI::App& app, RenderOptions& o) {
    CLI::App* cmd = app.add_subcommand("render", "Render frames of a scene to EXR + PNG + stats.json");
    cmd->add_option("--scene", o.scene, "builtin:NAME, .gltf/.glb, or scene .json")->capture_default_str();
    cmd->add_option("--width", o.width, "Image width in pixels")->check(CLI::Range(1, 16384))->capture_default_str();
    cmd->add_option("--height", o.height, "Image height in pixels")->check(CLI::Range(1, 16384))->capture_default_str();
    cmd->add_option("--spp", o.spp, "Samples per pixel per effect")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    cmd->add_option("--frames", o.frames, "Number of frames")->check(CLI::Range(1, 100000))->capture_default_str();
    cmd->add_option("--backend", o.backend, "Traversal back end")
        ->check(CLI::IsMember({"embree", "rtcore"}))
        ->capture_default_str();
    cmd->add_option("--rtcore-config", o.rtcoreConfig, "RT-core model parameters (JSON; docs/rtcore-model.md)");
    cmd->add_option("--rtcore-set", o.rtcoreSet, "Override one RT-core parameter: section.field=value (repeatable)")
        ->allow_extra_args(false);
    cmd->add_flag("--verify", o.verify, "With --backend rtcore: trace every ray on Embree too and report mismatches");
    cmd->add_option("--threads", o.threads, "Worker threads (0 = all cores)")->check(CLI::Range(0, 1024))->capture_default_str();
    cmd->add_option("--seed", o.seed, "Random seed")->capture_default_str();
    cmd->add_option("--out", o.out, "Output directory")->capture_default_str();
}

// The RT-core configuration of a render: defaults, then the JSON file, then
// each --rtcore-set in order. Bad keys and values are InputErrors (exit 2).
rtcore_sim::RtCoreConfig resolveRtCoreConfig(const RenderOptions& o) {
    rtcore_sim::RtCoreConfig config =
        o.rtcoreConfig.empty() ? rtcore_sim::RtCoreConfig{} : rtcore_sim::RtCoreConfig::loadFile(o.rtcoreConfig);
    for (const std::string& assignment : o.rtcoreSet) config.set(assignment);
    return config;
}

int runRender(const RenderOptions& o) {
    // Step: options that only mean something for the RT-core model.
    if (o.backend != "rtcore") {
        if (!o.rtcoreConfig.empty()) throw InputError("--rtcore-config", "only applies to --backend rtcore");
        if (!o.rtcoreSet.empty()) throw InputError("--rtcore-set", "only applies to --backend rtcore");
        if (o.verify) throw InputError("--verify", "only applies to --backend rtcore");
    }
    if (o.backend == "rtcore") {
        (void)resolveRtCoreConfig(o);  // validate first: a bad key is the clearer error
        throw InputError("--backend", "'rtcore' is not available yet in this build: the RT-core model is not "
                                      "wired into the pipeline yet (docs/rtcore-model.md); use embree");
    }
    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    if (ec || !std::filesystem::is_directory(o.out)) throw InputError(o.out, "cannot create output directory");

    const ThreadLimit threadLimit(o.threads);
    ecs::World world;
    const Stopwatch loadClock;
    ecs::load::loadScene(world, o.scene);
    const double loadMs = loadClock.elapsedMs();

    tracer::AccelOptions accelOptions;
    accelOptions.threads = o.threads;
    tracer::AccelManager accel(accelOptions);

    nlohmann::json stats;
    stats["scene"] = o.scene;
    stats["settings"] = {{"width", o.width}, {"height", o.height}, {"spp", o.spp}, {"frames", o.frames},
                         {"backend", o.backend}, {"seed", o.seed}};
    stats["timing"] = {{"loadMs", loadMs}};
    stats["frames"] = nlohmann::json::array();

    for (int f = 0; f < o.frames; ++f) {
        progress("rendering frame " + std::to_string(f + 1) + "/" + std::to_string(o.frames));
        // Step: systems -> what changed -> acceleration structures -> shading.
        const ecs::FrameUpdate update = world.update(f == 0 ? 0.f : world.settings().frameSeconds);
        const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, update);
        const tracer::AccelUpdateStats accelStats = accel.update(scene);
        const Stopwatch renderClock;
        const shaders::PreviewResult frame = shaders::renderPreview(accel, scene, {o.width, o.height});
        const double renderMs = renderClock.elapsedMs();

        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d", f);
        const std::filesystem::path base = std::filesystem::path(o.out) / name;
        writeExr(base.string() + ".exr", frame.image, ExrPixelType::Float);
        writePng(base.string() + ".png", frame.image);

        nlohmann::json fj;
        fj["frame"] = f;
        fj["time"] = update.time;
        fj["update"] = {{"moved", update.movedInstances.size()},
                        {"refit", update.refitMeshes.size()},
                        {"rebuilt", update.rebuiltMeshes.size()},
                        {"instanceSetChanged", update.instanceSetChanged}};
        fj["accel"] = {{"blasRebuilt", accelStats.blasRebuilt},
                       {"blasRebuiltForQuality", accelStats.blasRebuiltForQuality},
                       {"blasRefit", accelStats.blasRefit},
                       {"blasReused", accelStats.blasReused},
                       {"worstRefitDegradation", accelStats.worstRefitDegradation},
                       {"tlasBuilds", accelStats.tlasBuilds},
                       {"tlasUpdates", accelStats.tlasUpdates},
                       {"instancesMoved", accelStats.instancesMoved}};
        const tracer::TraceCounters& c = frame.counters;
        fj["rays"] = {{"primary", {{"traced", c.rays[0]}, {"hits", c.hits[0]}, {"misses", c.misses[0]}}}};
        fj["shaders"] = {{"anyHit", c.anyHitInvocations},
                         {"intersection", c.intersectionInvocations},
                         {"closestHit", c.closestHitInvocations},
                         {"miss", c.missInvocations},
                         {"packets", c.packetsTraced}};
        // Timings vary run to run; everything outside "timing" is deterministic.
        fj["timing"] = {{"accelBuildMs", accelStats.buildMs}, {"renderMs", renderMs}};
        stats["frames"].push_back(fj);
    }
    progress("");
    writeTextFileAtomically(std::filesystem::path(o.out) / "stats.json", stats.dump(2) + "\n");
    std::cerr << "rtlab: wrote " << o.frames << " frame(s) to " << o.out << "\n";
    return 0;
}

}  // namespace rtlab::app
