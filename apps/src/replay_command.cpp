// rtlab replay: recorded rays (rtlab render --record-rays) traced again
// without shading, on Embree or the RT-core model; stats.json has the same
// "rtcore" tree as render, and the hits that differ from the recorded ones
// (exit 1 when any do).
#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/session/frame_session.hpp>
#include <rtlab/study/replay.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>

namespace rtlab::app {
namespace {

// The ray-trace files of --rays: the file itself, or a directory's *.rays in name order.
std::vector<std::filesystem::path> rayFiles(const std::string& rays) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (!fs::exists(rays, ec)) throw InputError(rays, "no such file or directory");
    if (!fs::is_directory(rays, ec)) return {fs::path(rays)};
    std::vector<fs::path> files;
    for (const fs::directory_entry& e : fs::directory_iterator(rays, ec))
        if (e.is_regular_file() && e.path().extension() == ".rays") files.push_back(e.path());
    if (files.empty()) throw InputError(rays, "no .rays files in the directory");
    std::sort(files.begin(), files.end());
    return files;
}

}  // namespace

void addReplayCommand(CLI::App& app, ReplayOptions& o) {
    CLI::App* cmd =
        app.add_subcommand("replay", "Trace recorded rays again without shading (docs/ray-trace-format.md)");
    addFrameOptions(*cmd, o.frame, session::kUseReplay, true);
    cmd->add_option("--rays", o.rays, "A .rays file, or a directory of them (rtlab render --record-rays DIR)")
        ->required();
    cmd->add_option("--ray-types", o.rayTypes,
                    "all, or the recorded batches of these ray types only: primary,shadow,reflection,ao,gi,"
                    "translucency,pathBounce")
        ->capture_default_str();
}

int runReplay(const ReplayOptions& options) {
    const session::FrameOptions& o = options.frame;
    // Step: options and files, checked before the scene is loaded (--ray-types first, as always).
    const std::uint32_t typeMask = rayTypeMask(options.rayTypes);
    session::FrameSession s(o);
    std::map<std::uint32_t, study::RayTraceFile> byFrame;
    for (const std::filesystem::path& path : rayFiles(options.rays)) {
        study::RayTraceFile file = study::RayTraceFile::read(path);
        const std::uint32_t frame = file.header().frame;
        if (byFrame.count(frame))
            throw InputError(path.string(),
                             "frame " + std::to_string(frame) + " is also in " + byFrame.at(frame).path().string());
        byFrame.emplace(frame, std::move(file));
    }
    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    if (ec || !std::filesystem::is_directory(o.out)) throw InputError(o.out, "cannot create output directory");
    s.load();
    rtcore_sim::RtCoreBackend* rtcore = s.rtcore();

    nlohmann::json stats;
    stats["scene"] = o.scene;
    stats["rays"] = options.rays;
    stats["backend"] = o.backend;
    stats["rayTypes"] = options.rayTypes;
    if (rtcore) stats["rtcore"] = {{"config", rtcore->config().toJson()}};
    stats["frames"] = nlohmann::json::array();
    std::uint64_t differing = 0, replayed = 0;
    // Step: the scene advances frame by frame as in render (the model's BVH
    // refits and its cache see the same history); recorded frames are traced.
    const std::uint32_t lastFrame = byFrame.rbegin()->first;
    for (std::uint32_t f = 0; f <= lastFrame; ++f) {
        const ecs::SceneSnapshot& scene = s.advance().scene;
        const auto found = byFrame.find(f);
        if (found == byFrame.end()) continue;
        const study::RayTraceFile& file = found->second;
        study::checkReplayable(file, study::sceneFingerprint(scene), rtcore);
        progress("replaying frame " + std::to_string(f) + " (" + std::to_string(file.header().rayCount) + " rays)");
        if (rtcore) rtcore->beginFrame();
        study::ReplayResult r;
        try {
            r = study::replayRays(file, s.accel(), rtcore, typeMask);
        } catch (const InputError& e) {  // e.g. recorded verdicts that do not fit: the file's fault
            throw InputError(file.path().string(), e.what());
        }
        differing += r.differingHits;
        replayed += r.rays;

        nlohmann::json fj;
        fj["frame"] = f;
        fj["file"] = file.path().string();
        fj["recordedOn"] = file.info().backend == study::RecordedBackend::RtCore ? "rtcore" : "embree";
        fj["batches"] = r.batches;
        fj["rays"] = nlohmann::json::object();
        for (std::uint32_t t = 0; t < shaders::kRayTypeCount; ++t)
            if (r.counters.rays[t])
                fj["rays"][std::string(shaders::rayTypeName(t))] = {
                    {"traced", r.counters.rays[t]}, {"hits", r.counters.hits[t]}, {"misses", r.counters.misses[t]}};
        fj["differingHits"] = r.differingHits;
        fj["notBitIdentical"] = r.notBitIdentical;
        nlohmann::json examples = nlohmann::json::array();
        for (const study::DifferingHit& d : r.examples)
            examples.push_back({{"batch", d.batch},
                                {"lane", d.lane},
                                {"rayType", d.rayType},
                                {"origin", {d.ray.origin.x, d.ray.origin.y, d.ray.origin.z}},
                                {"direction", {d.ray.direction.x, d.ray.direction.y, d.ray.direction.z}},
                                {"recorded", hitJson(d.recorded)},
                                {"replayed", hitJson(d.replayed)}});
        fj["differingExamples"] = examples;
        fj["uniqueTriangles"] = file.info().uniqueTriangles;
        if (rtcore) {
            rtcore_sim::MemoryLayout layout;
            layout.build(rtcore->model());
            fj["rtcoreModelBytes"] = layout.totalBytes();
            nlohmann::json tree = rtcore->statsJson();
            tree.erase("config");  // echoed once, at the top level
            fj["rtcore"] = std::move(tree);
        }
        fj["timing"] = {{"replayMs", r.milliseconds},
                        {"raysPerSecond", r.milliseconds > 0.0 ? double(r.rays) / (r.milliseconds * 1e-3) : 0.0}};
        stats["frames"].push_back(std::move(fj));
    }
    progress("");
    writeTextFileAtomically(std::filesystem::path(o.out) / "stats.json", jsonText(stats) + "\n");
    std::cerr << "rtlab: replayed " << replayed << " rays of " << byFrame.size() << " frame(s) on " << o.backend << ", "
              << differing << " hit(s) differ from the recording; wrote " << o.out << "/stats.json\n";
    return differing > 0 ? 1 : 0;
}

}  // namespace rtlab::app
