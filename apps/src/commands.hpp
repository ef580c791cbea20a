#pragma once
// The rtlab subcommands. Each returns the process exit code; bad input is
// thrown as rtlab::InputError and turned into exit 2 by main().
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <rtlab/tracer/pipeline.hpp>
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace rtlab::ecs {
class World;
}

namespace rtlab::app {

struct RenderOptions {
    std::string scene = "builtin:showcase";
    int width = 640;
    int height = 360;
    int spp = 1;
    int frames = 1;
    std::string backend = "embree";
    std::string rtcoreConfig;               // --rtcore-config FILE (JSON)
    std::vector<std::string> rtcoreSet;     // --rtcore-set section.field=value, in order
    bool verify = false;                    // --verify: trace every ray on both back ends
    int threads = 0;
    std::uint32_t seed = 0;
    std::string out = "out";
    std::string effects = "auto";           // --effects auto|LIST
    std::string denoise = "auto";           // --denoise auto|none|LIST
    std::string gi = "path";                // --gi path|ddgi
    float reflectionRoughness = 0.3f;       // --reflection-roughness: reflections where roughness <= this
    float aoRadius = 1.0f;                  // --ao-radius (world units)
    int aoContactSamples = shaders::RenderSettings{}.aoContactExtraSamples;  // --ao-contact-samples
    int maxTranslucencyDepth = 8;           // --max-translucency-depth
    int maxDepth = 4;                       // --max-depth: path-tracer bounces (--effects pathtrace)
    std::string recordRays;                 // --record-rays DIR: DIR/frame_NNNN.rays per frame
};
void addRenderCommand(CLI::App& app, RenderOptions& options);
// --reflection-roughness, --ao-radius and --ao-contact-samples, shared by render and converge.
void addEffectSettingOptions(CLI::App& command, float& reflectionRoughness, float& aoRadius, int& aoContactSamples);
int runRender(const RenderOptions& options);

// --backend embree|rtcore, --rtcore-config FILE and --rtcore-set k=v..., shared by render and replay.
void addBackendOptions(CLI::App& command, std::string& backend, std::string& rtcoreConfig,
                       std::vector<std::string>& rtcoreSet);
// InputError (exit 2) when --rtcore-config or --rtcore-set come without --backend rtcore.
void checkRtCoreOptionsNeedRtCore(const std::string& backend, const std::string& rtcoreConfig,
                                  const std::vector<std::string>& rtcoreSet);

// A committed hit for stats.json ({"hit": false}, or t, instance, geometry, primitive).
nlohmann::json hitJson(const tracer::CommittedHit& hit);

// The RT-core configuration: defaults, then the JSON file (if any), then
// each section.field=value in order, validated. Bad keys and values are
// InputErrors (exit 2).
rtcore_sim::RtCoreConfig resolveRtCoreConfig(const std::string& configFile, const std::vector<std::string>& sets);

struct ReplayOptions {
    std::string scene;
    std::string rays;                       // a .rays file or a directory of frame_NNNN.rays
    std::string backend = "embree";
    std::string rtcoreConfig;
    std::vector<std::string> rtcoreSet;
    std::string rayTypes = "all";           // --ray-types all|LIST (primary,shadow,...)
    int threads = 0;
    std::string out = "out/replay";
};
void addReplayCommand(CLI::App& app, ReplayOptions& options);
int runReplay(const ReplayOptions& options);

struct PlanOptions {
    std::string scene;
    std::string effects = "auto";
    std::string gi = "path";
    bool json = false;
};
void addPlanCommand(CLI::App& app, PlanOptions& options);
int runPlan(const PlanOptions& options);
// --effects / --gi as the planner's options (InputError on unknown names).
shaders::PlanOptions planOptions(const std::string& effects, const std::string& gi);

struct InfoOptions {
    std::string scene;
};
void addInfoCommand(CLI::App& app, InfoOptions& options);
int runInfo(const InfoOptions& options);

struct CompareOptions {
    std::string a, b;
};
void addCompareCommand(CLI::App& app, CompareOptions& options);
int runCompare(const CompareOptions& options);

struct ConvergeOptions {
    std::string scene = "builtin:showcase";
    std::string effect;
    std::string out;                        // "" = out/converge/<scene>-<effect>
    std::string cache = "out/converge-cache";
    int width = 480;
    int height = 270;
    int referenceSpp = 4096;
    int maxSpp = 256;
    int denoiseMaxSpp = 4;
    int frames = 16;
    int threads = 0;
    std::uint32_t seed = 0;
    float reflectionRoughness = 0.3f;
    float aoRadius = 1.0f;
    int aoContactSamples = shaders::RenderSettings{}.aoContactExtraSamples;
};
void addConvergeCommand(CLI::App& app, ConvergeOptions& options);
int runConverge(const ConvergeOptions& options);

// Progress of long work on stderr. progress(line): a line rewritten in place,
// only when stderr is a terminal ("" clears it).
void progress(const std::string& line);
// One step of counted work (frames of a render, points of a sweep): on a
// terminal, "WHAT DONE/TOTAL[, DETAIL], ETA M:SS" rewritten in place (the ETA
// from the rate so far); otherwise, with logLine, one plain line per step
// "rtlab: WHAT DONE/TOTAL[, DETAIL]" (a log file or CI), else nothing.
struct ProgressStep {
    std::string what;
    std::size_t done = 0;
    std::size_t total = 0;
    double elapsedSeconds = 0.0;  // for done steps
    std::string detail;
};
void progress(const ProgressStep& step, bool logLine = false);
// "M:SS" (or "H:MM:SS") left for total - done steps at the rate so far; "?" before the first step.
std::string etaText(double elapsedSeconds, std::size_t done, std::size_t total);

struct SweepOptions {
    std::string study;
    std::string out;
    int jobs = 1;
};
void addSweepCommand(CLI::App& app, SweepOptions& options);
int runSweep(const SweepOptions& options);

struct ReportOptions {
    std::string dir;
};
void addReportCommand(CLI::App& app, ReportOptions& options);
int runReport(const ReportOptions& options);

// ecs::load::loadScene, then one "rtlab: warning: ..." line on stderr per
// warning the loaders recorded (World::loadReport(), e.g. skipped points/lines).
void loadSceneWithWarnings(ecs::World& world, const std::string& source);

}  // namespace rtlab::app
