// rtlab render: frames of a scene through the frame driver, written as EXR +
// PNG per frame and one stats.json (with --backend rtcore: the model's stats
// tree and heatmaps; with --record-rays: a ray-trace file per frame).
#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/timer.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/session/frame_session.hpp>
#include <rtlab/study/ray_recorder.hpp>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <memory>
#include <stdexcept>
#include <vector>

namespace rtlab::app {

void addRenderCommand(CLI::App& app, session::FrameOptions& o) {
    CLI::App* cmd = app.add_subcommand("render", "Render frames of a scene to EXR + PNG + stats.json");
    addFrameOptions(*cmd, o, session::kUseRender);
}

namespace {

namespace fs = std::filesystem;

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
nlohmann::json writeHeatmaps(const fs::path& base, int width, int height, const std::vector<std::uint32_t>& rayPixels,
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

// The PNG preview: the beauty, unless the planned effects put no light in it
// (no shadows, GI or path tracing: --effects ao, or gbuffer alone); then the
// signal that was asked for, the AO visibility (ao.V, grey) where AO ran, else
// the albedo. Returns the layer shown ("" for the beauty).
std::string writePreviewPng(const fs::path& png, const shaders::FramePlan& plan, const Image& frame) {
    using shaders::Pass;
    const bool lit = plan.has(Pass::Shadows) || plan.has(Pass::GlobalIllumination) || plan.has(Pass::PathTrace);
    const float* ao = frame.channel("ao.V");
    if (lit || (!ao && !frame.hasChannel("albedo.R"))) {
        writePng(png, frame);
        return "";
    }
    Image preview(frame.width(), frame.height());
    std::vector<vec3> rgb(frame.pixelCount());
    const auto albedo = frame.rgbPlanes("albedo");
    for (std::size_t p = 0; p < rgb.size(); ++p)
        rgb[p] = ao ? vec3(ao[p]) : vec3(albedo[0][p], albedo[1][p], albedo[2][p]);
    preview.addRgbLayer("", rgb);
    writePng(png, preview);
    return ao ? "ao.V" : "albedo";
}

// stats.json's top level: the scene, the settings, the load report.
nlohmann::json sessionJson(const session::FrameSession& s, double loadMs) {
    const session::FrameOptions& o = s.options();
    nlohmann::json stats;
    stats["scene"] = o.scene;
    stats["settings"] = o.toJson(session::kUseStatsEcho);
    if (s.rtcore()) stats["rtcore"] = {{"config", s.rtcore()->config().toJson()}};
    stats["timing"] = {{"loadMs", loadMs}};
    const ecs::LoadReport& report = s.world().loadReport();
    stats["load"] = {
        {"skippedPrimitives", {{"points", report.skippedPointPrimitives}, {"lines", report.skippedLinePrimitives}}},
        {"warnings", report.warnings}};
    stats["frames"] = nlohmann::json::array();
    return stats;
}

// What the frame's update and acceleration structures did.
void addUpdateJson(nlohmann::json& fj, const session::FrameState& frame) {
    const ecs::FrameUpdate& update = frame.update;
    const tracer::AccelUpdateStats& a = frame.accel;
    fj["time"] = update.time;
    fj["update"] = {{"moved", update.movedInstances.size()},
                    {"refit", update.refitMeshes.size()},
                    {"rebuilt", update.rebuiltMeshes.size()},
                    {"instanceSetChanged", update.instanceSetChanged}};
    fj["accel"] = {{"blasRebuilt", a.blasRebuilt},      {"blasRebuiltForQuality", a.blasRebuiltForQuality},
                   {"blasRepadded", a.blasRepadded},    {"blasRefit", a.blasRefit},
                   {"blasReused", a.blasReused},        {"worstRefitDegradation", a.worstRefitDegradation},
                   {"tlasBuilds", a.tlasBuilds},        {"tlasUpdates", a.tlasUpdates},
                   {"instancesMoved", a.instancesMoved}};
}

// The rays, passes and shader invocations of the frame.
void addWorkJson(nlohmann::json& fj, const session::FrameSession& s, const shaders::FrameOutput& frame) {
    const shaders::FramePlan& plan = s.frame().plan;
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
        fj["pathtrace"] = {{"maxDepth", s.options().maxDepth}, {"vertices", vertices}};
    }
    if (plan.has(shaders::Pass::GlobalIllumination) && plan.gi == shaders::GiTechnique::Ddgi) {
        const shaders::DdgiUpdateStats& d = frame.ddgi;
        fj["ddgi"] = {{"probes",
                       {{"active", d.activeProbes},
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
}

void addShaderJson(nlohmann::json& fj, const tracer::TraceCounters& c) {
    fj["shaders"] = {{"anyHit", c.anyHitInvocations},
                     {"intersection", c.intersectionInvocations},
                     {"closestHit", c.closestHitInvocations},
                     {"miss", c.missInvocations},
                     {"packets", c.packetsTraced}};
}

// The model's stats tree for the frame, its BVH work and the heatmaps.
nlohmann::json modelJson(const session::FrameSession& s, const nlohmann::json& heatmap) {
    const rtcore_sim::ModelUpdateStats& m = s.frame().model;
    nlohmann::json r = s.rtcore()->statsJson();
    r.erase("config");  // echoed once, at the top level
    r["bvhUpdate"] = {{"blasRebuilt", m.blasRebuilt},
                      {"blasRebuiltForQuality", m.blasRebuiltForQuality},
                      {"blasRefit", m.blasRefit},
                      {"blasReused", m.blasReused},
                      {"worstRefitDegradation", m.worstRefitDegradation},
                      {"tlasBuilds", m.tlasBuilds},
                      {"instancesMoved", m.instancesMoved}};
    r["heatmap"] = heatmap;
    if (s.options().verify) r["verify"] = verifyJson(s.rtcore()->verifyStats());
    return r;
}

// Acceleration-structure memory per unique triangle: the model's BVH layout
// and rtlab's watertight clusters are deterministic; what Embree holds
// depends on its build threads ("measured").
void addMemoryJson(nlohmann::json& fj, const session::FrameSession& s) {
    const std::uint64_t triangles = session::uniqueTriangles(s.frame().scene);
    const auto perTriangle = [&](double bytes) { return triangles ? bytes / double(triangles) : 0.0; };
    const tracer::AccelManager& accel = s.accel();
    fj["accelMemory"] = {{"uniqueTriangles", triangles},
                         {"watertightClusterBytes", accel.clusterBytes()},
                         {"watertightClusterBytesPerTriangle", perTriangle(double(accel.clusterBytes()))}};
    if (s.rtcore()) {
        rtcore_sim::MemoryLayout layout;
        layout.build(s.rtcore()->model());
        fj["accelMemory"]["rtcoreModelBytes"] = layout.totalBytes();
        fj["accelMemory"]["rtcoreModelBytesPerTriangle"] = perTriangle(double(layout.totalBytes()));
    }
    fj["measured"] = {{"embreeBytes", accel.embreeBytes()},
                      {"embreeBytesPerTriangle", perTriangle(double(accel.embreeBytes()))}};
}

void makeDirectory(const std::string& dir, const char* what) {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec || !fs::is_directory(dir)) throw InputError(dir, std::string("cannot create ") + what);
}

}  // namespace

int runRender(const session::FrameOptions& o) {
    // Step: options checked and the RT-core model configured before anything is loaded.
    session::FrameSession s(o);
    if (s.rtcore()) s.rtcore()->recordPrimaryRays(true);
    makeDirectory(o.out, "output directory");
    // Step: --record-rays wraps the back end (Embree or the model) in a recorder.
    std::unique_ptr<study::RecordingBackend> recorder;
    if (!o.recordRays.empty()) {
        makeDirectory(o.recordRays, "the --record-rays directory");
        recorder = std::make_unique<study::RecordingBackend>(s.rtcore());
    }
    const Stopwatch loadClock;
    s.load();
    nlohmann::json stats = sessionJson(s, loadClock.elapsedMs());

    const Stopwatch framesClock;
    for (int f = 0; f < o.frames; ++f) {
        progress(ProgressStep{"rendering: frames done", std::size_t(f), std::size_t(o.frames),
                              framesClock.elapsedMs() / 1000.0, ""});
        const session::FrameState& frame = s.advance();
        if (f == 0) stats["plan"] = frame.plan.toJson();
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d", f);
        const fs::path raysFile = fs::path(o.recordRays) / (std::string(name) + ".rays");
        // Step: render (through the recorder, if any), then denoise and compose again.
        if (recorder) recorder->beginFrame(raysFile);
        const Stopwatch renderClock;
        shaders::FrameOutput out = s.render(recorder.get());
        const double renderMs = renderClock.elapsedMs();
        if (recorder)
            recorder->endFrame(frame.index, study::sceneFingerprint(frame.scene), frame.scene.instances.size(),
                               session::uniqueTriangles(frame.scene));
        const Stopwatch denoiseClock;
        nlohmann::json denoised = nlohmann::json::array();
        for (const denoise::DenoisedLayer& d : s.denoise(out))
            denoised.push_back({{"layer", d.layer}, {"effect", d.effect}, {"stack", denoise::stackName(d.stack)}});
        const double denoiseMs = denoiseClock.elapsedMs();

        // Step: the frame's files, written at the same time (each one to a
        // temporary name, then renamed); every write runs, then the first
        // failed one's error in this order is rethrown.
        const fs::path base = fs::path(o.out) / name;
        std::string preview;
        nlohmann::json heatmap;
        std::vector<std::function<void()>> writes;
        writes.emplace_back([&] { writeExr(base.string() + ".exr", out.image, ExrPixelType::Float); });
        writes.emplace_back([&] { preview = writePreviewPng(base.string() + ".png", frame.plan, out.image); });
        if (out.ddgiAtlas.width() > 0)
            writes.emplace_back([&] { writeExr(base.string() + "_ddgi.exr", out.ddgiAtlas, ExrPixelType::Float); });
        if (s.rtcore())
            writes.emplace_back([&] {
                heatmap = writeHeatmaps(base, o.width, o.height, out.primaryRayPixels, s.rtcore()->primaryRays());
            });
        runAllInParallel(writes);
        if (f == 0 && !preview.empty())
            std::cerr << "rtlab: " << name << ".png shows " << preview
                      << (preview == "ao.V" ? " (the AO visibility)" : " (the surfaces' albedo)")
                      << ": the effects chosen put no light in the beauty; every layer is in the .exr\n";

        // Step: the frame's stats; everything outside "timing" and "measured" is deterministic.
        nlohmann::json fj;
        fj["frame"] = f;
        fj["preview"] = preview.empty() ? "beauty" : preview;
        addUpdateJson(fj, frame);
        addWorkJson(fj, s, out);
        if (recorder) fj["recordedRays"] = {{"file", raysFile.string()}, {"rays", recorder->recordedRays()}};
        fj["denoised"] = denoised;
        addShaderJson(fj, out.counters);
        if (s.rtcore()) {
            fj["rtcore"] = modelJson(s, heatmap);
            // Which pass each of rtcore.backend.launches is (a replay has launches, not passes).
            fj["launchPasses"] = nlohmann::json::array();
            for (const rtcore_sim::LaunchRecord& l : s.rtcore()->launches()) fj["launchPasses"].push_back(l.label);
        }
        addMemoryJson(fj, s);
        fj["timing"] = {{"accelBuildMs", frame.accel.buildMs}, {"renderMs", renderMs}, {"denoiseMs", denoiseMs}};
        for (std::size_t p = 0; p < shaders::kPassCount; ++p)
            if (frame.plan.passes[p].planned)
                fj["timing"]["passMs"][std::string(shaders::passName(static_cast<shaders::Pass>(p)))] =
                    out.passes[p].milliseconds;
        if (s.rtcore()) fj["timing"]["rtcoreBvhUpdateMs"] = frame.modelUpdateMs;
        stats["frames"].push_back(fj);
    }
    progress("");
    writeTextFileAtomically(fs::path(o.out) / "stats.json", jsonText(stats) + "\n");
    std::cerr << "rtlab: wrote " << o.frames << " frame(s) to " << o.out << "\n";
    if (!o.verify) return 0;
    // Totals over the frames' verify trees.
    std::uint64_t mismatches = 0, verified = 0;
    for (const nlohmann::json& fj : stats["frames"]) {
        mismatches += fj["rtcore"]["verify"]["mismatches"].get<std::uint64_t>();
        verified += fj["rtcore"]["verify"]["rays"].get<std::uint64_t>();
    }
    std::cerr << "rtlab: verify: " << verified << " rays traced on rtcore and embree, " << mismatches
              << " mismatch(es)\n";
    // A mismatch is the model's bug, not the input's: internal error.
    return mismatches > 0 ? static_cast<int>(ExitCode::Internal) : 0;
}

}  // namespace rtlab::app
