#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/timer.hpp>
#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>
#include <rtlab/study/ray_recorder.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>

namespace rtlab::app {

void addEffectSettingOptions(CLI::App& cmd, float& reflectionRoughness, float& aoRadius, int& aoContactSamples) {
    cmd.add_option("--reflection-roughness", reflectionRoughness, "Reflections trace where roughness <= this")
        ->check(CLI::Range(0.f, 1.f))
        ->capture_default_str();
    cmd.add_option("--ao-radius", aoRadius, "Ambient-occlusion ray length (world units)")
        ->check(CLI::Range(0.f, 1e30f))
        ->capture_default_str();
    cmd.add_option("--ao-contact-samples", aoContactSamples,
                   "More AO samples per sample at pixels next to a contact (an occluder nearer than a quarter of "
                   "--ao-radius within 2 pixels); 0 = the same count everywhere")
        ->check(CLI::Range(0, 1024))
        ->capture_default_str();
}

void addBackendOptions(CLI::App& cmd, std::string& backend, std::string& rtcoreConfig,
                       std::vector<std::string>& rtcoreSet) {
    cmd.add_option("--backend", backend, "Traversal back end")
        ->check(CLI::IsMember({"embree", "rtcore"}))
        ->capture_default_str();
    cmd.add_option("--rtcore-config", rtcoreConfig, "RT-core model parameters (JSON; docs/rtcore-model.md)");
    cmd.add_option("--rtcore-set", rtcoreSet, "Override one RT-core parameter: section.field=value (repeatable)")
        ->allow_extra_args(false);
}

void checkRtCoreOptionsNeedRtCore(const std::string& backend, const std::string& rtcoreConfig,
                                  const std::vector<std::string>& rtcoreSet) {
    if (backend == "rtcore") return;
    if (!rtcoreConfig.empty()) throw InputError("--rtcore-config", "only applies to --backend rtcore");
    if (!rtcoreSet.empty()) throw InputError("--rtcore-set", "only applies to --backend rtcore");
}

void addRenderCommand(CLI::App& app, RenderOptions& o) {
    CLI::App* cmd = app.add_subcommand("render", "Render frames of a scene to EXR + PNG + stats.json");
    cmd->add_option("--scene", o.scene, "builtin:NAME, .gltf/.glb, or scene .json")->capture_default_str();
    cmd->add_option("--width", o.width, "Image width in pixels")->check(CLI::Range(1, 16384))->capture_default_str();
    cmd->add_option("--height", o.height, "Image height in pixels")->check(CLI::Range(1, 16384))->capture_default_str();
    cmd->add_option("--spp", o.spp, "Samples per pixel per effect")->check(CLI::Range(1, 1 << 20))->capture_default_str();
    cmd->add_option("--frames", o.frames, "Number of frames")->check(CLI::Range(1, 100000))->capture_default_str();
    addBackendOptions(*cmd, o.backend, o.rtcoreConfig, o.rtcoreSet);
    cmd->add_flag("--verify", o.verify, "With --backend rtcore: trace every ray on Embree too and report mismatches");
    cmd->add_option("--threads", o.threads, "Worker threads (0 = all cores)")->check(CLI::Range(0, 1024))->capture_default_str();
    cmd->add_option("--seed", o.seed, "Random seed")->capture_default_str();
    cmd->add_option("--effects", o.effects, "auto (what the scene needs; see rtlab plan) or a comma-separated list "
                                            "narrowing it: alpha,shadows,reflections,ao,gi,translucency,volumes; "
                                            "pathtrace (multi-bounce paths, a ray workload) only when listed "
                                            "(gbuffer alone: primary rays only)")
        ->capture_default_str();
    cmd->add_option("--gi", o.gi, "Diffuse GI technique")->check(CLI::IsMember({"path", "ddgi"}))->capture_default_str();
    addEffectSettingOptions(*cmd, o.reflectionRoughness, o.aoRadius, o.aoContactSamples);
    cmd->add_option("--max-translucency-depth", o.maxTranslucencyDepth,
                    "Refraction/reflection events along a translucent path")
        ->check(CLI::Range(1, 64))
        ->capture_default_str();
    cmd->add_option("--max-depth", o.maxDepth, "Path-tracer bounces after the primary hit (--effects pathtrace)")
        ->check(CLI::Range(0, 64))
        ->capture_default_str();
    cmd->add_option("--denoise", o.denoise,
                    "auto (every effect's signal), none, or a comma-separated list of shadows,reflections,ao,gi,"
                    "translucency,volumes: SVGF per signal layer, noisy layers kept as noisy.*")
        ->capture_default_str();
    cmd->add_option("--record-rays", o.recordRays,
                    "Write every ray as submitted to the back end, with its hit, to DIR/frame_NNNN.rays "
                    "(docs/ray-trace-format.md; rtlab replay)");
    cmd->add_option("--out", o.out, "Output directory")->capture_default_str();
}

rtcore_sim::RtCoreConfig resolveRtCoreConfig(const std::string& configFile, const std::vector<std::string>& sets) {
    rtcore_sim::RtCoreConfig config =
        configFile.empty() ? rtcore_sim::RtCoreConfig{} : rtcore_sim::RtCoreConfig::loadFile(configFile);
    for (const std::string& assignment : sets) config.set(assignment);
    config.validate(configFile.empty() ? "--rtcore-set" : configFile);
    return config;
}

nlohmann::json hitJson(const tracer::CommittedHit& h) {
    if (!h.hit) return {{"hit", false}};
    return {{"hit", true}, {"t", h.t}, {"instance", h.instanceIndex}, {"geometry", h.geometryIndex},
            {"primitive", h.primitiveIndex}};
}

namespace {

nlohmann::json verifyJson(const rtcore_sim::VerifyStats& v) {
    nlohmann::json examples = nlohmann::json::array();
    for (const rtcore_sim::HitMismatch& m : v.examples)
        examples.push_back({{"rayType", m.rayType},
                            {"depth", m.depth},
                            {"origin", {m.ray.origin.x, m.ray.origin.y, m.ray.origin.z}},
                            {"direction", {m.ray.direction.x, m.ray.direction.y, m.ray.direction.z}},
                            {"rtcore", hitJson(m.model)},
                            {"embree", hitJson(m.embree)}});
    return {{"rays", v.rays},
            {"mismatches", v.mismatches},
            {"notBitIdentical", v.notBitIdentical},
            {"hitOnlyRays", v.anyHitOnlyRays},
            {"maxRelativeTDifference", v.maxRelativeTDifference},
            {"examples", examples}};
}

// Per-pixel heatmaps of the primary rays the model traced: EXR layers
// rtcore.cycles (latency: submission -> result), rtcore.slotCycles (time in
// a ray slot: traversal, fetches, unit waits, no queue waits) and
// rtcore.nodeVisits, plus false-colour PNGs of slot cycles and node visits
// (scale: the 99th percentile, so one slow ray cannot flatten the map).
nlohmann::json writeHeatmaps(const std::filesystem::path& base, int width, int height,
                             const std::vector<std::uint32_t>& rayPixels,
                             const std::vector<rtcore_sim::PrimaryRayRecord>& records) {
    if (rayPixels.size() != records.size())
        throw std::logic_error("heatmap: " + std::to_string(rayPixels.size()) + " primary rays generated but " +
                               std::to_string(records.size()) + " traced by the model");
    Image heat(width, height);
    float* cycles = heat.addChannel("rtcore.cycles");
    float* slotCycles = heat.addChannel("rtcore.slotCycles");
    float* nodes = heat.addChannel("rtcore.nodeVisits");
    for (std::size_t i = 0; i < records.size(); ++i) {
        cycles[rayPixels[i]] += static_cast<float>(records[i].cycles);
        slotCycles[rayPixels[i]] += static_cast<float>(records[i].slotCycles);
        nodes[rayPixels[i]] += static_cast<float>(records[i].nodeVisits);
    }
    writeExr(base.string() + "_rtcore.exr", heat, ExrPixelType::Float);
    nlohmann::json scales;
    const auto falseColourPng = [&](const float* values, const std::string& suffix, const std::string& key) {
        const float scale = quantile(values, heat.pixelCount(), 0.99);
        std::vector<vec3> rgb(heat.pixelCount());
        for (std::size_t p = 0; p < heat.pixelCount(); ++p) rgb[p] = falseColour(values[p], scale);
        Image image(width, height);
        image.addRgbLayer("", rgb);
        writePng(base.string() + suffix, image);
        scales[key] = scale;
    };
    falseColourPng(slotCycles, "_rtcore_cycles.png", "slotCyclesScaleMax");
    falseColourPng(nodes, "_rtcore_nodes.png", "nodeVisitsScaleMax");
    return scales;
}

}  // namespace

int runRender(const RenderOptions& o) {
    // Step: options that only mean something for the RT-core model.
    checkRtCoreOptionsNeedRtCore(o.backend, o.rtcoreConfig, o.rtcoreSet);
    if (o.backend != "rtcore" && o.verify) throw InputError("--verify", "only applies to --backend rtcore");
    // Step: options checked before anything is loaded.
    shaders::PlanOptions planOptions = app::planOptions(o.effects, o.gi);
    planOptions.reflectionMaxRoughness = o.reflectionRoughness;
    std::unique_ptr<denoise::EffectLayerDenoiser> denoiser;
    if (o.denoise != "none") {
        std::vector<std::string> effects;
        if (o.denoise != "auto") {
            std::stringstream in(o.denoise);
            std::string item;
            while (std::getline(in, item, ','))
                if (!item.empty()) effects.push_back(item);
            if (effects.empty()) throw InputError("--denoise", "empty list (use auto, none or effect names)");
        }
        try {
            denoiser = std::make_unique<denoise::EffectLayerDenoiser>(effects);
        } catch (const std::invalid_argument& e) {
            throw InputError("--denoise", std::string(e.what()) + " (known: auto, none, shadows, reflections, ao, gi, "
                                                                  "translucency, volumes)");
        }
    }
    // Step: the RT-core model, configured before anything is loaded (a bad key is the clearer error).
    std::unique_ptr<rtcore_sim::RtCoreBackend> rtcore;
    if (o.backend == "rtcore") {
        rtcore = std::make_unique<rtcore_sim::RtCoreBackend>(resolveRtCoreConfig(o.rtcoreConfig, o.rtcoreSet));
        rtcore->recordPrimaryRays(true);
        rtcore->setVerify(o.verify);
    }
    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    if (ec || !std::filesystem::is_directory(o.out)) throw InputError(o.out, "cannot create output directory");
    // Step: --record-rays wraps the back end (Embree or the model) in a recorder.
    std::unique_ptr<study::RecordingBackend> recorder;
    if (!o.recordRays.empty()) {
        std::filesystem::create_directories(o.recordRays, ec);
        if (ec || !std::filesystem::is_directory(o.recordRays))
            throw InputError(o.recordRays, "cannot create the --record-rays directory");
        recorder = std::make_unique<study::RecordingBackend>(rtcore.get());
    }

    const ThreadLimit threadLimit(o.threads);
    ecs::World world;
    const Stopwatch loadClock;
    loadSceneWithWarnings(world, o.scene);
    const double loadMs = loadClock.elapsedMs();

    tracer::AccelOptions accelOptions;
    accelOptions.threads = o.threads;
    tracer::AccelManager accel(accelOptions);

    nlohmann::json stats;
    stats["scene"] = o.scene;
    stats["settings"] = {{"width", o.width}, {"height", o.height}, {"spp", o.spp}, {"frames", o.frames},
                         {"backend", o.backend}, {"seed", o.seed}, {"verify", o.verify}};
    stats["settings"]["effects"] = o.effects;
    stats["settings"]["gi"] = o.gi;
    stats["settings"]["reflectionRoughness"] = o.reflectionRoughness;
    stats["settings"]["aoRadius"] = o.aoRadius;
    stats["settings"]["aoContactSamples"] = o.aoContactSamples;
    stats["settings"]["maxTranslucencyDepth"] = o.maxTranslucencyDepth;
    stats["settings"]["maxDepth"] = o.maxDepth;
    stats["settings"]["denoise"] = o.denoise;
    if (rtcore) stats["rtcore"] = {{"config", rtcore->config().toJson()}};
    shaders::FrameHistory history;
    std::uint64_t totalMismatches = 0, totalVerified = 0;
    stats["timing"] = {{"loadMs", loadMs}};
    const ecs::LoadReport& report = world.loadReport();
    stats["load"] = {{"skippedPrimitives",
                      {{"points", report.skippedPointPrimitives}, {"lines", report.skippedLinePrimitives}}},
                     {"warnings", report.warnings}};
    stats["frames"] = nlohmann::json::array();

    const Stopwatch framesClock;
    for (int f = 0; f < o.frames; ++f) {
        progress(ProgressStep{"rendering: frames done", std::size_t(f), std::size_t(o.frames),
                              framesClock.elapsedMs() / 1000.0, ""});
        // Step: systems -> what changed -> acceleration structures -> shading.
        const ecs::FrameUpdate update = world.update(f == 0 ? 0.f : world.settings().frameSeconds);
        const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, update);
        const tracer::AccelUpdateStats accelStats = accel.update(scene);
        const shaders::FramePlan plan = shaders::planFrame(scene, planOptions);
        if (f == 0) {
            stats["plan"] = plan.toJson();
            for (const std::string& note : plan.notes) std::cerr << "rtlab: note: " << note << "\n";
        }
        shaders::RenderSettings settings;
        settings.width = o.width;
        settings.height = o.height;
        settings.spp = o.spp;
        settings.frame = static_cast<std::uint32_t>(f);
        settings.seed = o.seed;
        settings.aoRadius = o.aoRadius;
        settings.aoContactExtraSamples = o.aoContactSamples;
        settings.maxTranslucencyDepth = o.maxTranslucencyDepth;
        settings.pathMaxDepth = o.maxDepth;
        rtcore_sim::ModelUpdateStats modelStats;
        const Stopwatch modelClock;
        if (rtcore) {
            modelStats = rtcore->update(scene);
            rtcore->beginFrame();
            settings.backend = rtcore.get();
            settings.recordRayOrder = true;
        }
        const double modelBuildMs = modelClock.elapsedMs();
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d", f);
        if (recorder) {
            recorder->beginFrame(std::filesystem::path(o.recordRays) / (std::string(name) + ".rays"));
            settings.backend = recorder.get();
        }
        const Stopwatch renderClock;
        shaders::FrameOutput frame = shaders::renderFrame(accel, scene, plan, settings, history);
        const double renderMs = renderClock.elapsedMs();
        std::uint64_t uniqueTriangles = 0;
        for (const ecs::MeshAsset& mesh : *scene.meshes)
            for (const ecs::Geometry& g : mesh.geometries) uniqueTriangles += g.triangleCount();
        if (recorder)
            recorder->endFrame(static_cast<std::uint32_t>(f), study::sceneFingerprint(scene), scene.instances.size(),
                               uniqueTriangles);
        // Step: denoise the effect signals, keep the noisy beauty, compose again.
        nlohmann::json denoised = nlohmann::json::array();
        const Stopwatch denoiseClock;
        if (denoiser) {
            frame.image.addRgbLayer("noisy", frame.image.rgbLayer(""));
            for (const denoise::DenoisedLayer& d : denoiser->apply(frame.image))
                denoised.push_back({{"layer", d.layer}, {"effect", d.effect}, {"stack", denoise::stackName(d.stack)}});
            shaders::composeBeauty(frame.image);
        }
        const double denoiseMs = denoiseClock.elapsedMs();

        const std::filesystem::path base = std::filesystem::path(o.out) / name;
        writeExr(base.string() + ".exr", frame.image, ExrPixelType::Float);
        writePng(base.string() + ".png", frame.image);
        if (frame.ddgiAtlas.width() > 0) writeExr(base.string() + "_ddgi.exr", frame.ddgiAtlas, ExrPixelType::Float);
        nlohmann::json heatmap;
        if (rtcore) heatmap = writeHeatmaps(base, o.width, o.height, frame.primaryRayPixels, rtcore->primaryRays());

        nlohmann::json fj;
        fj["frame"] = f;
        fj["time"] = update.time;
        fj["update"] = {{"moved", update.movedInstances.size()},
                        {"refit", update.refitMeshes.size()},
                        {"rebuilt", update.rebuiltMeshes.size()},
                        {"instanceSetChanged", update.instanceSetChanged}};
        fj["accel"] = {{"blasRebuilt", accelStats.blasRebuilt},
                       {"blasRebuiltForQuality", accelStats.blasRebuiltForQuality},
                       {"blasRepadded", accelStats.blasRepadded},
                       {"blasRefit", accelStats.blasRefit},
                       {"blasReused", accelStats.blasReused},
                       {"worstRefitDegradation", accelStats.worstRefitDegradation},
                       {"tlasBuilds", accelStats.tlasBuilds},
                       {"tlasUpdates", accelStats.tlasUpdates},
                       {"instancesMoved", accelStats.instancesMoved}};
        const tracer::TraceCounters& c = frame.counters;
        fj["rays"] = nlohmann::json::object();
        for (std::uint32_t t = 0; t < shaders::kRayTypeCount; ++t)
            fj["rays"][std::string(shaders::rayTypeName(t))] = {
                {"traced", c.rays[t]}, {"hits", c.hits[t]}, {"misses", c.misses[t]}};
        if (plan.has(shaders::Pass::PathTrace)) {
            nlohmann::json vertices = nlohmann::json::array();
            for (std::size_t d = 0; d < frame.pathVertices.size(); ++d)
                vertices.push_back({{"vertex", d},
                                    {"bounceRays", frame.pathVertices[d].bounceRays},
                                    {"bounceHits", frame.pathVertices[d].bounceHits},
                                    {"shadowRays", frame.pathVertices[d].shadowRays}});
            fj["pathtrace"] = {{"maxDepth", o.maxDepth}, {"vertices", vertices}};
        }
        if (plan.has(shaders::Pass::GlobalIllumination) && plan.gi == shaders::GiTechnique::Ddgi) {
            const shaders::DdgiUpdateStats& d = frame.ddgi;
            fj["ddgi"] = {{"probes", {{"active", d.activeProbes},
                                      {"relocating", d.relocatingProbes},
                                      {"inside", d.insideProbes},
                                      {"idle", d.idleProbes},
                                      {"traced", d.tracedProbes},
                                      {"moved", d.movedProbes},
                                      {"offset", d.offsetProbes}}},
                          {"rays", d.rays},
                          {"misses", d.misses},
                          {"backfaceHits", d.backfaceHits}};
        }
        fj["passes"] = nlohmann::json::object();
        for (std::size_t p = 0; p < shaders::kPassCount; ++p)
            fj["passes"][std::string(shaders::passName(static_cast<shaders::Pass>(p)))] = {
                {"planned", plan.passes[p].planned},
                {"rays", frame.passes[p].rays},
                {"bytesAllocated", frame.passes[p].bytesAllocated}};
        fj["nonFiniteValuesRepaired"] = frame.nonFiniteValuesRepaired;
        if (recorder)
            fj["recordedRays"] = {{"file", (std::filesystem::path(o.recordRays) / (std::string(name) + ".rays")).string()},
                                  {"rays", recorder->recordedRays()}};
        fj["denoised"] = denoised;
        fj["shaders"] = {{"anyHit", c.anyHitInvocations},
                         {"intersection", c.intersectionInvocations},
                         {"closestHit", c.closestHitInvocations},
                         {"miss", c.missInvocations},
                         {"packets", c.packetsTraced}};
        if (rtcore) {
            nlohmann::json r = rtcore->statsJson();
            r.erase("config");  // echoed once, at the top level
            r["bvhUpdate"] = {{"blasRebuilt", modelStats.blasRebuilt},
                              {"blasRebuiltForQuality", modelStats.blasRebuiltForQuality},
                              {"blasRefit", modelStats.blasRefit},
                              {"blasReused", modelStats.blasReused},
                              {"worstRefitDegradation", modelStats.worstRefitDegradation},
                              {"tlasBuilds", modelStats.tlasBuilds},
                              {"instancesMoved", modelStats.instancesMoved}};
            r["heatmap"] = heatmap;
            if (o.verify) {
                const rtcore_sim::VerifyStats& v = rtcore->verifyStats();
                r["verify"] = verifyJson(v);
                totalMismatches += v.mismatches;
                totalVerified += v.rays;
            }
            fj["rtcore"] = std::move(r);
        }
        // Acceleration-structure memory per unique triangle: the model's BVH
        // layout and rtlab's watertight clusters are deterministic; what
        // Embree holds depends on its build threads ("measured" below).
        auto perTriangle = [&](double bytes) { return uniqueTriangles ? bytes / double(uniqueTriangles) : 0.0; };
        fj["accelMemory"] = {{"uniqueTriangles", uniqueTriangles},
                             {"watertightClusterBytes", accel.clusterBytes()},
                             {"watertightClusterBytesPerTriangle", perTriangle(double(accel.clusterBytes()))}};
        if (rtcore) {
            rtcore_sim::MemoryLayout layout;
            layout.build(rtcore->model());
            fj["accelMemory"]["rtcoreModelBytes"] = layout.totalBytes();
            fj["accelMemory"]["rtcoreModelBytesPerTriangle"] = perTriangle(double(layout.totalBytes()));
        }
        fj["measured"] = {{"embreeBytes", accel.embreeBytes()},
                          {"embreeBytesPerTriangle", perTriangle(double(accel.embreeBytes()))}};
        // Timings vary run to run; everything outside "timing" and "measured" is deterministic.
        fj["timing"] = {{"accelBuildMs", accelStats.buildMs}, {"renderMs", renderMs}, {"denoiseMs", denoiseMs}};
        for (std::size_t p = 0; p < shaders::kPassCount; ++p)
            if (plan.passes[p].planned)
                fj["timing"]["passMs"][std::string(shaders::passName(static_cast<shaders::Pass>(p)))] =
                    frame.passes[p].milliseconds;
        if (rtcore) fj["timing"]["rtcoreBvhUpdateMs"] = modelBuildMs;
        stats["frames"].push_back(fj);
    }
    progress("");
    writeTextFileAtomically(std::filesystem::path(o.out) / "stats.json", stats.dump(2) + "\n");
    std::cerr << "rtlab: wrote " << o.frames << " frame(s) to " << o.out << "\n";
    if (o.verify) {
        std::cerr << "rtlab: verify: " << totalVerified << " rays traced on rtcore and embree, " << totalMismatches
                  << " mismatch(es)\n";
        // A mismatch is the model's bug, not the input's: internal error.
        if (totalMismatches > 0) return static_cast<int>(ExitCode::Internal);
    }
    return 0;
}

}  // namespace rtlab::app
