#pragma once
// A study (docs/studies.md): workloads x RT-core configurations, each pair one
// point, each point one `rtlab render` (or `rtlab replay`). A STUDY.json file names
//
//   "workloads": scene sources ("builtin:cornell", {"scene": "a.gltf"}) or
//                recorded rays ({"scene": SRC, "rays": "out/rays"});
//   "render":    the render settings every point shares (width, height, ...);
//   "base":      {"section.field": value} overrides applied to every point;
//   "grid":      {"section.field": [values...]}: the cartesian product;
//   "list":      [{"section.field": value, ...}, ...]: explicit override sets.
//
// The override sets of a study are the grid's product (keys in sorted order,
// the last key varying fastest) followed by the list's entries; the points
// are workloads x override sets, workload-major. Bad input throws
// rtlab::InputError naming the file and the key.
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/session/frame_options.hpp>

#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace rtlab::study {

// One workload: a scene to render, or recorded rays to replay on it
// ({"rays": FILE or DIR, "scene": SRC}: `rtlab replay`, traversal only, no
// shading; docs/ray-trace-format.md).
struct Workload {
    std::string scene;
    std::string rays;    // empty: render the scene
    std::string camera;  // empty: the scene's; else a --camera value (rendered workloads only)

    nlohmann::json toJson() const;
    // The label of rows and plots: the scene source, and the rays when
    // replayed or the camera when set.
    std::string label() const {
        if (!rays.empty()) return scene + " [rays " + rays + "]";
        return camera.empty() ? scene : scene + " [camera " + camera + "]";
    }
};

// Settings every point of the study renders with: the `rtlab render`
// options (session::FrameOptions, read from the study's "render" object by
// their keys), with a sweep's defaults: 64x64, the RT-core model, no
// denoising (sweeps measure traversal). `threads` is per point; 0 = the
// sweep chooses (cores / concurrent points).
session::FrameOptions defaultStudyRender();
// The render settings as the study's fingerprint sees them: every study
// option but threads (results do not depend on it), rtcoreConfig only when set.
nlohmann::json studyRenderJson(const session::FrameOptions& render);

// One "section.field=value" override.
struct Override {
    std::string key;       // "cache.sizeBytes"
    nlohmann::json value;  // 4096, "treelet", true

    // The value as `--rtcore-set` takes it: strings bare, everything else as JSON.
    std::string valueText() const;
    std::string assignment() const { return key + "=" + valueText(); }
};
using OverrideSet = std::vector<Override>;

// The most points a study may have (workloads x override sets): a bound on
// what a small file can ask for (each point is a render), checked before the
// points are expanded.
inline constexpr std::uint64_t kMaxStudyPoints = 100000;

struct Study {
    std::vector<Workload> workloads;
    session::FrameOptions render = defaultStudyRender();
    OverrideSet base;
    std::vector<std::pair<std::string, std::vector<nlohmann::json>>> grid;  // sorted by key
    std::vector<OverrideSet> list;
    // The metrics the report's summary ranks configurations by ("objective":
    // a metric name or a list of them; default cycles).
    std::vector<std::string> objectives = {"cycles"};

    // The canonical form: what the study means, independent of formatting
    // and key order. Two files with the same canonical form are the same study.
    // "objective" appears only when it is not the default.
    nlohmann::json toJson() const;
    // A 16-hex-digit hash of toJson().dump() without "objective" (how results
    // are ranked does not change them: a study resumes after it changes).
    std::string fingerprint() const;
};

// Parses a study; `where` (the file name) prefixes every error. With
// checkPoints, every point's whole RT-core configuration is resolved and
// validated too (reading render.rtcoreConfig), every builtin workload's name
// and parameters are checked and every scene and rays file must exist (without: a
// stored study, reported or read back).
Study parseStudy(const nlohmann::json& json, const std::string& where, bool checkPoints = true);
// Reads and parses STUDY.json (InputError naming the file when unreadable or invalid).
Study loadStudy(const std::filesystem::path& path);

struct Point {
    std::size_t index = 0;
    std::string id;  // "p0000", "p0001", ... in point order
    Workload workload;
    OverrideSet overrides;  // this point's grid / list overrides (without "base")
};

// Every point of the study, in order.
std::vector<Point> expandPoints(const Study& study);
// The swept parameters: the grid's keys, then keys first seen in the list.
std::vector<std::string> sweptParameters(const Study& study);
// The value `point` gives parameter `key` (null when it does not set it).
nlohmann::json overrideValue(const Point& point, const std::string& key);

// The RT-core configuration of a point: defaults, the study's rtcoreConfig
// file, "base", then the point's overrides (validated; InputError naming the
// study file and the point). With point == nullptr: the base configuration.
rtcore_sim::RtCoreConfig resolveConfig(const Study& study, const Point* point, const std::string& where);

// The `rtlab render` arguments of a point (`rtlab replay` for a ray-trace
// workload) without the program name, writing into `outDir`, with `threads`
// threads (0 = all cores).
std::vector<std::string> renderArguments(const Study& study, const Point& point, const std::string& outDir,
                                         int threads);
// A command line for a shell: each argument quoted when it needs to be.
std::string shellCommand(const std::vector<std::string>& arguments);

}  // namespace rtlab::study
