#pragma once
// The options of a frame sequence, in one place: every command that renders
// (render, converge, replay, plan, a study's points, the benchmarks) reads
// its settings from a FrameOptions, and FrameSession (frame_session.hpp) is
// the only code that turns them into shaders::RenderSettings.
//
// Each option is one row of frameOptionFields(): its flag, its stats.json /
// study key, its help, its range and which commands take it. The command line
// registers the rows (apps/src/cli_common.cpp), a study reads its "render"
// object through them and writes a point's command line with toArgs(), and
// stats.json echoes them. A new option is a member here plus one row in
// frame_options.cpp (and its use in FrameSession::renderSettings).
#include <rtlab/core/math.hpp>
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace rtlab::session {

// The most frames one render makes (--frames); a recorded frame's index is
// below it (the ray-trace reader checks: a replay advances the scene to it).
inline constexpr int kMaxFrames = 100000;

// A --camera value, parsed: where the camera is and what it looks at, or
// "interior": a camera placed from the scene's bounds once it is loaded (at
// the centre of the horizontal extent, 35% up the height, looking along the
// longer horizontal axis toward its positive end, 60-degree field of view: the
// walk-through view of an atrium or a room such as Sponza's).
struct CameraPlacement {
    bool interior = false;
    vec3 eye{0.f}, target{0.f, 0.f, -1.f}, up{0.f, 1.f, 0.f};
    float fovYDegrees = 45.f;
};
// Parses "interior" or "ex,ey,ez,tx,ty,tz[,ux,uy,uz[,fovYDegrees]]" (up
// defaults to +Y, the field of view to 45 degrees). InputError naming `flag`
// on anything else: not 6, 9 or 10 finite numbers, eye equal to target, up
// zero or along the view, a field of view outside (0, 180).
CameraPlacement parseCameraPlacement(const std::string& text, const std::string& flag = "--camera");
// What can be checked of a scene source without loading it (InputError
// naming the source): a builtin: source's name and parameters, a file's
// existence. A file's contents are checked when it is read.
void checkSceneSource(const std::string& source);

struct FrameOptions {
    std::string scene = "builtin:showcase";  // builtin:NAME[?k=v...], .gltf/.glb, .obj, .ply, .fbx, or scene .json
    std::string camera;  // "" = the scene's (or the default); else "ex,ey,ez,tx,ty,tz[,ux,uy,uz[,fovYDegrees]]"
    int width = 640;
    int height = 360;
    int spp = 1;  // samples per pixel per effect
    int frames = 1;
    std::uint32_t seed = 0;
    int threads = 0;                     // 0 = all cores
    std::string backend = "embree";      // embree | rtcore
    std::string rtcoreConfig;            // JSON file of RT-core parameters
    std::vector<std::string> rtcoreSet;  // section.field=value, applied in order after rtcoreConfig
    bool verify = false;                 // rtcore: trace every ray on Embree too
    bool opaque = false;                 // trace alpha-masked materials as opaque (no any-hit alpha test)
    std::string effects = "auto";        // auto | comma-separated pass names
    std::string denoise = "auto";        // auto | none | comma-separated effect names
    std::string gi = "path";             // path | ddgi
    float reflectionRoughness = 0.3f;    // reflections trace where roughness <= this
    float aoRadius = 1.0f;               // world units
    int aoContactSamples = 8;            // shaders::RenderSettings::aoContactExtraSamples
    int maxTranslucencyDepth = 8;
    int maxDepth = 4;        // path-tracer bounces (--effects pathtrace)
    std::string recordRays;  // DIR for frame_NNNN.rays ("" = no recording)
    std::string out = "out";

    // Range and cross-field checks (InputError naming the option); the
    // command line checks ranges as it parses, a study file or a program
    // filling the struct gets the same checks here.
    void validate() const;
    // --effects, --gi and --reflection-roughness as the planner's options (InputError on unknown names).
    shaders::PlanOptions planOptions() const;
    // --denoise as effect names for denoise::EffectLayerDenoiser: empty for
    // auto (every effect); not to be called for none (denoises() is false).
    std::vector<std::string> denoiseList() const;
    bool denoises() const { return denoise != "none"; }
    // The RT-core configuration: defaults, then rtcoreConfig (if any), then
    // each rtcoreSet assignment in order, validated (InputError on bad keys and values).
    rtcore_sim::RtCoreConfig rtcoreConfiguration() const;

    // The options that commands of kind `use` take (OptionUse bits), as
    // command-line arguments, each only where it differs from `defaults`.
    std::vector<std::string> toArgs(unsigned use, const FrameOptions& defaults) const;
    std::vector<std::string> toArgs(unsigned use) const;  // against FrameOptions{}
    // The fields with the given use bit as a JSON object keyed by FrameOptionField::key.
    nlohmann::json toJson(unsigned use) const;
    // Sets the field with this key from a JSON value (a study's "render"
    // object): InputError(where, "PREFIX.KEY: ...") on a wrong type or range.
    void setFromJson(std::string_view key, const nlohmann::json& value, const std::string& where,
                     const std::string& prefix);
};

// Which commands take an option (bits of FrameOptionField::uses).
enum OptionUse : unsigned {
    kUseRender = 1u << 0,
    kUseConverge = 1u << 1,
    kUseReplay = 1u << 2,
    kUsePlan = 1u << 3,
    kUseStudy = 1u << 4,      // a study's "render" object
    kUseStatsEcho = 1u << 5,  // echoed in render's stats.json "settings"
};

struct FrameOptionField {
    using Member =
        std::variant<int FrameOptions::*, float FrameOptions::*, std::uint32_t FrameOptions::*,
                     std::string FrameOptions::*, bool FrameOptions::*, std::vector<std::string> FrameOptions::*>;
    std::string flag;  // "--max-translucency-depth"
    std::string key;   // "maxTranslucencyDepth" (stats.json settings, study render object)
    std::string help;
    Member member;
    bool ranged = false;  // numeric fields: checked against [min, max] (range())
    double min = 0, max = 0;
    std::vector<std::string> choices;  // string fields: the accepted values (empty = any)
    unsigned uses = 0;                 // OptionUse bits

    FrameOptionField& range(double lo, double hi) {
        ranged = true;
        min = lo;
        max = hi;
        return *this;
    }
    FrameOptionField& oneOf(std::vector<std::string> values) {
        choices = std::move(values);
        return *this;
    }
};

// Every option, in the order help lists them.
const std::vector<FrameOptionField>& frameOptionFields();
const FrameOptionField* frameOptionByKey(std::string_view key);

}  // namespace rtlab::session
