// The frame options' table: one row per option (flag, key, help, range,
// which commands take it), and what is derived from it.
#include <rtlab/session/frame_options.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/shaders_cpp/effect_table.hpp>

#include <algorithm>
#include <filesystem>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <sstream>
#include <type_traits>

namespace rtlab::session {
namespace {

using F = FrameOptions;
constexpr unsigned kRenderLike = kUseRender | kUseStudy | kUseStatsEcho;

// One row: flag, key, member, uses and help; .range() or .oneOf() as the field needs.
FrameOptionField field(std::string flag, std::string key, FrameOptionField::Member member, unsigned uses,
                       std::string help) {
    FrameOptionField f;
    f.flag = std::move(flag);
    f.key = std::move(key);
    f.member = member;
    f.uses = uses;
    f.help = std::move(help);
    return f;
}

std::vector<FrameOptionField> makeFields() {
    const std::string listable = shaders::effectNames(shaders::EffectFilter::Listable);
    const std::string denoised = shaders::effectNames(shaders::EffectFilter::Denoised);
    // Step: one row per option. Ranges are those the command line always had.
    const unsigned all = kUseRender | kUseConverge | kUseReplay | kUsePlan;
    return {
        field("--scene", "scene", &F::scene, all,
              "builtin:NAME[?k=v&...], .gltf/.glb, .obj, .ply, .fbx, or scene .json"),
        field("--camera", "camera", &F::camera, kUseRender | kUseStatsEcho | kUseConverge,
              "The camera instead of the scene's: eyeX,eyeY,eyeZ,targetX,targetY,targetZ[,upX,upY,upZ[,fovYDegrees]] "
              "(up defaults to +Y, the field of view to 45 degrees), or interior (inside the scene's bounds, looking "
              "along their longer horizontal axis: an atrium or room such as Sponza)"),
        field("--width", "width", &F::width, kRenderLike | kUseConverge, "Image width in pixels").range(1, 16384),
        field("--height", "height", &F::height, kRenderLike | kUseConverge, "Image height in pixels").range(1, 16384),
        field("--spp", "spp", &F::spp, kRenderLike, "Samples per pixel per effect").range(1, 1 << 20),
        field("--frames", "frames", &F::frames, kRenderLike, "Number of frames").range(1, kMaxFrames),
        field("--backend", "backend", &F::backend, kRenderLike | kUseReplay, "Traversal back end")
            .oneOf({"embree", "rtcore"}),
        field("--rtcore-config", "rtcoreConfig", &F::rtcoreConfig, kUseRender | kUseReplay | kUseStudy,
              "RT-core model: a preset (single-core, rtx2060-like, h100-like; default rtx2060-like) or a JSON "
              "file (docs/rtcore-model.md, \"Presets\")"),
        field("--rtcore-set", "rtcoreSet", &F::rtcoreSet, kUseRender | kUseReplay,
              "Override one RT-core parameter: section.field=value (repeatable)"),
        field("--verify", "verify", &F::verify, kUseRender | kUseStatsEcho,
              "With --backend rtcore: trace every ray on Embree too and report mismatches"),
        field("--opaque", "opaque", &F::opaque, kRenderLike | kUseConverge | kUsePlan,
              "Trace alpha-masked materials as opaque (no any-hit alpha test). By default alpha masks are "
              "geometry: tested on every ray type whatever --effects lists"),
        field("--threads", "threads", &F::threads, kUseRender | kUseConverge | kUseReplay | kUseStudy,
              "Worker threads (0 = all cores)")
            .range(0, 1024),
        field("--seed", "seed", &F::seed, kRenderLike | kUseConverge, "Random seed").range(0, 4294967295.0),
        field("--effects", "effects", &F::effects, kRenderLike | kUsePlan,
              "auto (what the scene needs; see rtlab plan) or a comma-separated list narrowing it: " + listable +
                  "; pathtrace (multi-bounce paths, a ray workload) only when listed (gbuffer alone: primary "
                  "rays only)"),
        field("--gi", "gi", &F::gi, kRenderLike | kUsePlan, "Diffuse GI technique").oneOf({"path", "ddgi"}),
        field("--reflection-roughness", "reflectionRoughness", &F::reflectionRoughness,
              kRenderLike | kUseConverge | kUsePlan, "Reflections trace where roughness <= this")
            .range(0, 1),
        field("--ao-radius", "aoRadius", &F::aoRadius, kRenderLike | kUseConverge,
              "Ambient-occlusion ray length (world units)")
            .range(0, 1e30),
        field("--ao-contact-samples", "aoContactSamples", &F::aoContactSamples, kRenderLike | kUseConverge,
              "More AO samples per sample at pixels next to a contact (an occluder nearer than a quarter of "
              "--ao-radius within 2 pixels); 0 = the same count everywhere")
            .range(0, 1024),
        field("--max-translucency-depth", "maxTranslucencyDepth", &F::maxTranslucencyDepth, kRenderLike | kUseConverge,
              "Refraction/reflection events along a translucent path")
            .range(1, 64),
        field("--max-depth", "maxDepth", &F::maxDepth, kRenderLike,
              "Path-tracer bounces after the primary hit (--effects pathtrace)")
            .range(0, 64),
        field("--denoise", "denoise", &F::denoise, kRenderLike,
              "auto (every effect's signal), none, or a comma-separated list of " + denoised +
                  ": SVGF per signal layer, noisy layers kept as noisy.*"),
        field("--record-rays", "recordRays", &F::recordRays, kUseRender,
              "Write every ray as submitted to the back end, with its hit, to DIR/frame_NNNN.rays "
              "(docs/ray-trace-format.md; rtlab replay)"),
        field("--out", "out", &F::out, kUseRender | kUseReplay, "Output directory"),
    };
}

// Whole numbers below 1e15 as integers ("4294967295"), others as %.9g.
std::string formatNumber(double v) {
    char buf[64];
    if (v == double(static_cast<long long>(v)) && v < 1e15 && v > -1e15)
        std::snprintf(buf, sizeof buf, "%lld", static_cast<long long>(v));
    else std::snprintf(buf, sizeof buf, "%.9g", v);
    return buf;
}

std::string joinChoices(const std::vector<std::string>& choices) {
    std::string s;
    for (const std::string& c : choices) s += (s.empty() ? "" : ", ") + c;
    return s;
}

// A field's value as command-line text ("" for a list: each item is its own argument).
std::string argText(const FrameOptions& o, const FrameOptionField& f) {
    return std::visit(
        [&](auto member) -> std::string {
            using T = std::remove_cvref_t<decltype(o.*member)>;
            const T& v = o.*member;
            if constexpr (std::is_same_v<T, std::string>) return v;
            else if constexpr (std::is_same_v<T, float>) return formatNumber(v);
            else if constexpr (std::is_same_v<T, bool>) return v ? "true" : "false";
            else if constexpr (std::is_same_v<T, std::vector<std::string>>) return {};
            else return std::to_string(v);
        },
        f.member);
}

}  // namespace

const std::vector<FrameOptionField>& frameOptionFields() {
    static const std::vector<FrameOptionField> fields = makeFields();
    return fields;
}

const FrameOptionField* frameOptionByKey(std::string_view key) {
    for (const FrameOptionField& f : frameOptionFields())
        if (f.key == key) return &f;
    return nullptr;
}

void checkSceneSource(const std::string& source) {
    const std::string prefix = "builtin:";
    if (source.rfind(prefix, 0) == 0) {
        ecs::load::checkBuiltinScene(source.substr(prefix.size()));
        return;
    }
    std::error_code ec;
    if (!std::filesystem::exists(source, ec)) throw InputError(source, "no such file");
    if (!std::filesystem::is_regular_file(source, ec)) throw InputError(source, "not a regular file");
}

CameraPlacement parseCameraPlacement(const std::string& text, const std::string& flag) {
    if (text == "interior") {
        CameraPlacement c;
        c.interior = true;
        c.fovYDegrees = 60.f;
        return c;
    }
    std::vector<float> v;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) {
        char* end = nullptr;
        const float x = std::strtof(item.c_str(), &end);
        if (item.empty() || end != item.c_str() + item.size() || !std::isfinite(x))
            throw InputError(flag, "'" + item + "' is not a finite number");
        v.push_back(x);
    }
    if (v.size() != 6 && v.size() != 9 && v.size() != 10)
        throw InputError(flag, "expected 6, 9 or 10 numbers: eye, target[, up[, fovY in degrees]] (got " +
                                   std::to_string(v.size()) + ")");
    CameraPlacement c;
    c.eye = vec3(v[0], v[1], v[2]);
    c.target = vec3(v[3], v[4], v[5]);
    if (v.size() >= 9) c.up = vec3(v[6], v[7], v[8]);
    if (v.size() == 10) c.fovYDegrees = v[9];
    const vec3 along = c.target - c.eye;
    if (!(glm::length(along) > 0.f)) throw InputError(flag, "eye and target are the same point");
    if (!(glm::length(glm::cross(along, c.up)) > 1e-6f * glm::length(along) * glm::length(c.up)))
        throw InputError(flag, "the up vector is zero or along the view direction");
    if (!(c.fovYDegrees > 0.f && c.fovYDegrees < 180.f)) throw InputError(flag, "fovY must be in (0, 180) degrees");
    return c;
}

void FrameOptions::validate() const {
    // Step: each field in its range or among its choices.
    for (const FrameOptionField& f : frameOptionFields()) {
        std::visit(
            [&](auto member) {
                using T = std::remove_cvref_t<decltype(this->*member)>;
                const T& v = this->*member;
                if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
                    // In the member's own type: a float option's bound is the float nearest to it.
                    if (f.ranged && !(v >= static_cast<T>(f.min) && v <= static_cast<T>(f.max)))
                        throw InputError(f.flag, "must be in " + formatNumber(f.min) + ".." + formatNumber(f.max) +
                                                     " (got " + formatNumber(double(v)) + ")");
                } else if constexpr (std::is_same_v<T, std::string>) {
                    if (!f.choices.empty() && std::find(f.choices.begin(), f.choices.end(), v) == f.choices.end())
                        throw InputError(f.flag, "must be one of " + joinChoices(f.choices) + " (got '" + v + "')");
                }
            },
            f.member);
    }
    if (!camera.empty()) parseCameraPlacement(camera);
    // Step: options that only mean something for the RT-core model.
    if (backend != "rtcore") {
        if (!rtcoreConfig.empty()) throw InputError("--rtcore-config", "only applies to --backend rtcore");
        if (!rtcoreSet.empty()) throw InputError("--rtcore-set", "only applies to --backend rtcore");
        if (verify) throw InputError("--verify", "only applies to --backend rtcore");
    }
}

shaders::PlanOptions FrameOptions::planOptions() const {
    shaders::PlanOptions options;
    options.requested = shaders::parseEffectList(effects);
    options.gi = gi == "ddgi" ? shaders::GiTechnique::Ddgi : shaders::GiTechnique::Path;
    options.opaque = opaque;
    options.reflectionMaxRoughness = reflectionRoughness;
    return options;
}

std::vector<std::string> FrameOptions::denoiseList() const {
    std::vector<std::string> list;
    if (denoise == "auto") return list;
    std::stringstream in(denoise);
    std::string item;
    while (std::getline(in, item, ','))
        if (!item.empty()) list.push_back(item);
    if (list.empty()) throw InputError("--denoise", "empty list (use auto, none or effect names)");
    for (const std::string& name : list) {
        const shaders::EffectRow* row = shaders::effectRowByName(name);
        if (!row || row->denoiseStack.empty())
            throw InputError("--denoise", "unknown effect '" + name + "' (known: auto, none, " +
                                              shaders::effectNames(shaders::EffectFilter::Denoised, ", ") + ")");
    }
    return list;
}

rtcore_sim::RtCoreConfig FrameOptions::rtcoreConfiguration() const {
    rtcore_sim::RtCoreConfig config = rtcore_sim::RtCoreConfig::load(rtcoreConfig);
    for (const std::string& assignment : rtcoreSet) config.set(assignment);
    config.validate(rtcoreConfig.empty() ? "--rtcore-set" : rtcoreConfig);
    config.checkExplicitKeys("--rtcore-set");
    return config;
}

std::vector<std::string> FrameOptions::toArgs(unsigned use, const FrameOptions& defaults) const {
    std::vector<std::string> args;
    for (const FrameOptionField& f : frameOptionFields()) {
        if (!(f.uses & use)) continue;
        if (const auto* list = std::get_if<std::vector<std::string> FrameOptions::*>(&f.member)) {
            for (const std::string& item : this->**list) args.insert(args.end(), {f.flag, item});
            continue;
        }
        const std::string value = argText(*this, f), fallback = argText(defaults, f);
        if (value == fallback) continue;
        if (std::holds_alternative<bool FrameOptions::*>(f.member)) args.push_back(f.flag);  // a flag: only when set
        else args.insert(args.end(), {f.flag, value});
    }
    return args;
}

std::vector<std::string> FrameOptions::toArgs(unsigned use) const { return toArgs(use, FrameOptions{}); }

nlohmann::json FrameOptions::toJson(unsigned use) const {
    nlohmann::json j = nlohmann::json::object();
    for (const FrameOptionField& f : frameOptionFields())
        if (f.uses & use) std::visit([&](auto member) { j[f.key] = this->*member; }, f.member);
    return j;
}

void FrameOptions::setFromJson(std::string_view key, const nlohmann::json& value, const std::string& where,
                               const std::string& prefix) {
    const FrameOptionField* f = frameOptionByKey(key);
    if (!f) throw InputError(where, prefix + std::string(key) + ": unknown option");
    const std::string path = prefix + f->key;
    std::visit(
        [&](auto member) {
            using T = std::remove_cvref_t<decltype(this->*member)>;
            T& v = this->*member;
            if constexpr (std::is_same_v<T, int> || std::is_same_v<T, std::uint32_t>) {
                const bool ok = std::is_same_v<T, int> ? value.is_number_integer() : value.is_number_unsigned();
                if (!ok ||
                    (f->ranged && (double(value.get<long long>()) < f->min || double(value.get<long long>()) > f->max)))
                    throw InputError(where, path + ": must be an integer in " + formatNumber(f->min) + ".." +
                                                formatNumber(f->max) + " (got " + value.dump() + ")");
                v = value.get<T>();
            } else if constexpr (std::is_same_v<T, float>) {
                if (!value.is_number() ||
                    (f->ranged && !(value.get<double>() >= f->min && value.get<double>() <= f->max)))
                    throw InputError(where, path + ": must be a number in " + formatNumber(f->min) + ".." +
                                                formatNumber(f->max) + " (got " + value.dump() + ")");
                v = value.get<float>();
            } else if constexpr (std::is_same_v<T, bool>) {
                if (!value.is_boolean())
                    throw InputError(where, path + ": must be true or false (got " + value.dump() + ")");
                v = value.get<bool>();
            } else if constexpr (std::is_same_v<T, std::string>) {
                if (!value.is_string() || value.get<std::string>().empty())
                    throw InputError(where, path + ": must be a non-empty string (got " + value.dump() + ")");
                const std::string s = value.get<std::string>();
                if (!f->choices.empty() && std::find(f->choices.begin(), f->choices.end(), s) == f->choices.end())
                    throw InputError(where,
                                     path + ": must be one of " + joinChoices(f->choices) + " (got \"" + s + "\")");
                v = s;
            } else {
                if (!value.is_array()) throw InputError(where, path + ": must be a list of strings");
                v.clear();
                for (const nlohmann::json& item : value) {
                    if (!item.is_string()) throw InputError(where, path + ": must be a list of strings");
                    v.push_back(item.get<std::string>());
                }
            }
        },
        f->member);
}

}  // namespace rtlab::session
