// The frame options' table: one row per option (flag, key, help, range,
// which commands take it), and what is derived from it.
#include <rtlab/session/frame_options.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/shaders_cpp/effect_table.hpp>

#include <algorithm>
#include <cstdio>
#include <sstream>
#include <type_traits>

namespace rtlab::session {
namespace {

using F = FrameOptions;
constexpr unsigned kRenderLike = kUseRender | kUseStudy | kUseStatsEcho;

std::vector<FrameOptionField> makeFields() {
    const std::string listable = shaders::effectNames(shaders::EffectFilter::Listable);
    const std::string denoised = shaders::effectNames(shaders::EffectFilter::Denoised);
    // Step: one row per option. Ranges are those the command line always had.
    return {
        {"--scene", "scene", "builtin:NAME[?k=v&...], .gltf/.glb, or scene .json", &F::scene, 0, 0, {},
         kUseRender | kUseConverge | kUseReplay | kUsePlan},
        {"--width", "width", "Image width in pixels", &F::width, 1, 16384, {}, kRenderLike | kUseConverge},
        {"--height", "height", "Image height in pixels", &F::height, 1, 16384, {}, kRenderLike | kUseConverge},
        {"--spp", "spp", "Samples per pixel per effect", &F::spp, 1, 1 << 20, {}, kRenderLike},
        {"--frames", "frames", "Number of frames", &F::frames, 1, 100000, {}, kRenderLike},
        {"--backend", "backend", "Traversal back end", &F::backend, 0, 0, {"embree", "rtcore"},
         kRenderLike | kUseReplay},
        {"--rtcore-config", "rtcoreConfig", "RT-core model parameters (JSON; docs/rtcore-model.md)", &F::rtcoreConfig,
         0, 0, {}, kUseRender | kUseReplay | kUseStudy},
        {"--rtcore-set", "rtcoreSet", "Override one RT-core parameter: section.field=value (repeatable)",
         &F::rtcoreSet, 0, 0, {}, kUseRender | kUseReplay},
        {"--verify", "verify", "With --backend rtcore: trace every ray on Embree too and report mismatches",
         &F::verify, 0, 0, {}, kUseRender | kUseStatsEcho},
        {"--threads", "threads", "Worker threads (0 = all cores)", &F::threads, 0, 1024, {},
         kUseRender | kUseConverge | kUseReplay | kUseStudy},
        {"--seed", "seed", "Random seed", &F::seed, 0, 4294967295.0, {}, kRenderLike | kUseConverge},
        {"--effects", "effects",
         "auto (what the scene needs; see rtlab plan) or a comma-separated list narrowing it: " + listable +
             "; pathtrace (multi-bounce paths, a ray workload) only when listed (gbuffer alone: primary rays only)",
         &F::effects, 0, 0, {}, kRenderLike | kUsePlan},
        {"--gi", "gi", "Diffuse GI technique", &F::gi, 0, 0, {"path", "ddgi"}, kRenderLike | kUsePlan},
        {"--reflection-roughness", "reflectionRoughness", "Reflections trace where roughness <= this",
         &F::reflectionRoughness, 0, 1, {}, kRenderLike | kUseConverge | kUsePlan},
        {"--ao-radius", "aoRadius", "Ambient-occlusion ray length (world units)", &F::aoRadius, 0, 1e30, {},
         kRenderLike | kUseConverge},
        {"--ao-contact-samples", "aoContactSamples",
         "More AO samples per sample at pixels next to a contact (an occluder nearer than a quarter of --ao-radius "
         "within 2 pixels); 0 = the same count everywhere",
         &F::aoContactSamples, 0, 1024, {}, kRenderLike | kUseConverge},
        {"--max-translucency-depth", "maxTranslucencyDepth", "Refraction/reflection events along a translucent path",
         &F::maxTranslucencyDepth, 1, 64, {}, kRenderLike | kUseConverge},
        {"--max-depth", "maxDepth", "Path-tracer bounces after the primary hit (--effects pathtrace)", &F::maxDepth,
         0, 64, {}, kRenderLike},
        {"--denoise", "denoise",
         "auto (every effect's signal), none, or a comma-separated list of " + denoised +
             ": SVGF per signal layer, noisy layers kept as noisy.*",
         &F::denoise, 0, 0, {}, kRenderLike},
        {"--record-rays", "recordRays",
         "Write every ray as submitted to the back end, with its hit, to DIR/frame_NNNN.rays "
         "(docs/ray-trace-format.md; rtlab replay)",
         &F::recordRays, 0, 0, {}, kUseRender},
        {"--out", "out", "Output directory", &F::out, 0, 0, {}, kUseRender | kUseReplay},
    };
}

// Whole numbers below 1e15 as integers ("4294967295"), others as %.9g.
std::string formatNumber(double v) {
    char buf[64];
    if (v == double(static_cast<long long>(v)) && v < 1e15 && v > -1e15)
        std::snprintf(buf, sizeof buf, "%lld", static_cast<long long>(v));
    else
        std::snprintf(buf, sizeof buf, "%.9g", v);
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

void FrameOptions::validate() const {
    // Step: each field in its range or among its choices.
    for (const FrameOptionField& f : frameOptionFields()) {
        std::visit(
            [&](auto member) {
                using T = std::remove_cvref_t<decltype(this->*member)>;
                const T& v = this->*member;
                if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
                    if (!(double(v) >= f.min && double(v) <= f.max))
                        throw InputError(f.flag, "must be in " + formatNumber(f.min) + ".." + formatNumber(f.max) +
                                                     " (got " + formatNumber(double(v)) + ")");
                } else if constexpr (std::is_same_v<T, std::string>) {
                    if (!f.choices.empty() && std::find(f.choices.begin(), f.choices.end(), v) == f.choices.end())
                        throw InputError(f.flag, "must be one of " + joinChoices(f.choices) + " (got '" + v + "')");
                }
            },
            f.member);
    }
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
    rtcore_sim::RtCoreConfig config =
        rtcoreConfig.empty() ? rtcore_sim::RtCoreConfig{} : rtcore_sim::RtCoreConfig::loadFile(rtcoreConfig);
    for (const std::string& assignment : rtcoreSet) config.set(assignment);
    config.validate(rtcoreConfig.empty() ? "--rtcore-set" : rtcoreConfig);
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
                if (!ok || double(value.get<long long>()) < f->min || double(value.get<long long>()) > f->max)
                    throw InputError(where, path + ": must be an integer in " + formatNumber(f->min) + ".." +
                                                formatNumber(f->max) + " (got " + value.dump() + ")");
                v = value.get<T>();
            } else if constexpr (std::is_same_v<T, float>) {
                if (!value.is_number() || !(value.get<double>() >= f->min && value.get<double>() <= f->max))
                    throw InputError(where, path + ": must be a number in " + formatNumber(f->min) + ".." +
                                                formatNumber(f->max) + " (got " + value.dump() + ")");
                v = value.get<float>();
            } else if constexpr (std::is_same_v<T, bool>) {
                if (!value.is_boolean()) throw InputError(where, path + ": must be true or false (got " + value.dump() + ")");
                v = value.get<bool>();
            } else if constexpr (std::is_same_v<T, std::string>) {
                if (!value.is_string() || value.get<std::string>().empty())
                    throw InputError(where, path + ": must be a non-empty string (got " + value.dump() + ")");
                const std::string s = value.get<std::string>();
                if (!f->choices.empty() && std::find(f->choices.begin(), f->choices.end(), s) == f->choices.end())
                    throw InputError(where, path + ": must be one of " + joinChoices(f->choices) + " (got \"" + s + "\")");
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
