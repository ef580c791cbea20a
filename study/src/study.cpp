#include <rtlab/study/study.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/json_nesting.hpp>
#include <rtlab/study/metrics.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>

namespace rtlab::study {

namespace {

using nlohmann::json;

std::string joinKeys(std::initializer_list<const char*> keys) {
    std::string s;
    for (const char* k : keys) s += (s.empty() ? "" : ", ") + std::string(k);
    return s;
}

void rejectUnknownKeys(const json& object, std::initializer_list<const char*> known, const std::string& where,
                       const std::string& prefix) {
    for (const auto& [key, value] : object.items()) {
        bool found = false;
        for (const char* k : known) found = found || key == k;
        if (!found) throw InputError(where, prefix + key + ": unknown key (known: " + joinKeys(known) + ")");
    }
}

std::string stringField(const json& object, const char* key, const std::string& fallback, const std::string& where,
                        const std::string& path, std::initializer_list<const char*> allowed = {}) {
    if (!object.contains(key)) return fallback;
    const json& v = object.at(key);
    if (!v.is_string() || v.get<std::string>().empty())
        throw InputError(where, path + ": must be a non-empty string (got " + v.dump() + ")");
    const std::string s = v.get<std::string>();
    if (allowed.size() != 0) {
        bool ok = false;
        for (const char* a : allowed) ok = ok || s == a;
        if (!ok) throw InputError(where, path + ": must be one of " + joinKeys(allowed) + " (got \"" + s + "\")");
    }
    return s;
}

// A parameter value: a number, a bool or a string (a choice such as a policy name).
void checkScalar(const json& value, const std::string& where, const std::string& path) {
    if (!(value.is_number() || value.is_boolean() || value.is_string()))
        throw InputError(where, path + ": must be a number, a boolean or a string (got " + value.dump() + ")");
}

OverrideSet parseOverrideObject(const json& object, const std::string& where, const std::string& path) {
    if (!object.is_object()) throw InputError(where, path + ": must be an object {\"section.field\": value}");
    OverrideSet set;
    for (const auto& [key, value] : object.items()) {
        Override o{key, value};
        checkScalar(value, where, path + "." + key);
        rtcore_sim::RtCoreConfig scratch;
        scratch.set(o.assignment(), where + ": " + path);
        set.push_back(std::move(o));
    }
    return set;
}

// checkSources: the scene and rays files exist and a builtin scene's name and
// parameters are valid (not for a stored study being reported or resumed).
Workload parseWorkload(const json& w, const std::string& where, const std::string& path, bool checkSources) {
    Workload workload;
    if (w.is_string()) {
        workload.scene = w.get<std::string>();
    } else if (w.is_object()) {
        rejectUnknownKeys(w, {"scene", "rays", "camera"}, where, path + ".");
        if (!w.contains("scene"))
            throw InputError(where, path + ": needs \"scene\" (a scene source; with \"rays\", the recorded scene)");
        workload.scene = stringField(w, "scene", "", where, path + ".scene");
        if (w.contains("rays")) {
            workload.rays = stringField(w, "rays", "", where, path + ".rays");
            if (workload.rays.empty())
                throw InputError(where,
                                 path + ".rays: empty (a .rays file or directory from rtlab render --record-rays)");
            std::error_code ec;
            if (checkSources && !std::filesystem::exists(workload.rays, ec))
                throw InputError(where, path + ".rays: " + workload.rays + ": no such file or directory");
        }
        if (w.contains("camera")) {
            workload.camera = stringField(w, "camera", "", where, path + ".camera");
            if (!workload.rays.empty())
                throw InputError(where, path + ".camera: a recorded workload replays its rays as recorded (no camera)");
            session::parseCameraPlacement(workload.camera, where + ": " + path + ".camera");
        }
    } else {
        throw InputError(where, path + ": must be a scene source string or {\"scene\": SRC} (got " + w.dump() + ")");
    }
    if (workload.scene.empty()) throw InputError(where, path + ": empty scene source");
    try {
        if (checkSources)
            session::checkSceneSource(workload.scene);  // an unknown builtin is refused before any point runs
    } catch (const InputError& e) {
        throw InputError(where, path + ": " + e.what());
    }
    return workload;
}

// "--effects: unknown effect ..." (an option's check) as "render.effects: unknown effect ...".
std::string asStudyKey(const std::string& message) {
    for (const session::FrameOptionField& f : session::frameOptionFields())
        if (message.rfind(f.flag + ": ", 0) == 0) return "render." + f.key + message.substr(f.flag.size());
    return "render: " + message;
}

std::string hex64(std::uint64_t v) {
    char buf[17];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
    return buf;
}

}  // namespace

json Workload::toJson() const {
    json j = {{"scene", scene}};
    if (!rays.empty()) j["rays"] = rays;
    if (!camera.empty()) j["camera"] = camera;
    return j;
}

session::FrameOptions defaultStudyRender() {
    session::FrameOptions o;
    o.width = 64;
    o.height = 64;
    o.backend = "rtcore";
    o.denoise = "none";
    o.scene.clear();  // each point's workload
    o.out.clear();    // each point's directory
    return o;
}

json studyRenderJson(const session::FrameOptions& render) {
    // The keys a study had before the options' table: always written (the
    // fingerprint of a study directory made then stays the same); any other
    // only when it differs from its default, so that a new option does not
    // change the fingerprint of studies that leave it alone.
    static const std::set<std::string> always = {"width",   "height",  "spp", "frames", "backend",
                                                 "effects", "denoise", "gi",  "seed"};
    const json defaults = defaultStudyRender().toJson(session::kUseStudy);
    json j = render.toJson(session::kUseStudy);
    for (auto it = j.begin(); it != j.end();) {
        const bool keep = it.key() != "threads" && (always.count(it.key()) || *it != defaults.at(it.key()));
        it = keep ? std::next(it) : j.erase(it);
    }
    return j;
}

std::string Override::valueText() const { return value.is_string() ? value.get<std::string>() : value.dump(); }

json Study::toJson() const {
    json j;
    j["workloads"] = json::array();
    for (const Workload& w : workloads) j["workloads"].push_back(w.toJson());
    j["render"] = studyRenderJson(render);
    j["base"] = json::object();
    for (const Override& o : base) j["base"][o.key] = o.value;
    j["grid"] = json::object();
    for (const auto& [key, values] : grid) j["grid"][key] = values;
    j["list"] = json::array();
    for (const OverrideSet& set : list) {
        json entry = json::object();
        for (const Override& o : set) entry[o.key] = o.value;
        j["list"].push_back(entry);
    }
    if (objectives != std::vector<std::string>{"cycles"}) j["objective"] = objectives;
    return j;
}

std::string Study::fingerprint() const {
    std::uint64_t h = 1469598103934665603ull;  // FNV-1a 64
    json canonical = toJson();
    canonical.erase("objective");
    for (const unsigned char c : canonical.dump()) {
        h ^= c;
        h *= 1099511628211ull;
    }
    return hex64(h);
}

Study parseStudy(const json& j, const std::string& where, bool checkPoints) {
    if (!j.is_object()) throw InputError(where, "a study must be a JSON object");
    rejectUnknownKeys(j, {"workloads", "render", "base", "grid", "list", "objective"}, where, "");
    Study study;
    // Step: the objective: metric names of metricList().
    if (j.contains("objective")) {
        const json& o = j.at("objective");
        std::vector<std::string> names;
        if (o.is_string()) names.push_back(o.get<std::string>());
        else if (o.is_array() && !o.empty() &&
                 std::all_of(o.begin(), o.end(), [](const json& v) { return v.is_string(); }))
            for (const json& v : o) names.push_back(v.get<std::string>());
        else
            throw InputError(where,
                             "objective: must be a metric name or a non-empty list of them (got " + o.dump() + ")");
        std::string known;
        for (const MetricInfo& m : metricList()) known += (known.empty() ? "" : ", ") + m.name;
        for (const std::string& name : names)
            if (std::none_of(metricList().begin(), metricList().end(),
                             [&](const MetricInfo& m) { return m.name == name; }))
                throw InputError(where, "objective: unknown metric '" + name + "' (known: " + known + ")");
        study.objectives = names;
    }

    // Step: workloads.
    if (!j.contains("workloads")) throw InputError(where, "workloads: missing (a list of scene sources)");
    const json& workloads = j.at("workloads");
    if (!workloads.is_array() || workloads.empty())
        throw InputError(where, "workloads: must be a non-empty list of scene sources");
    for (std::size_t i = 0; i < workloads.size(); ++i)
        study.workloads.push_back(
            parseWorkload(workloads[i], where, "workloads[" + std::to_string(i) + "]", checkPoints));

    // Step: render settings.
    if (j.contains("render")) {
        const json& r = j.at("render");
        if (!r.is_object()) throw InputError(where, "render: must be an object");
        // Every option a study may set is a row of session::frameOptionFields():
        // unknown keys first, then each value, then the checks across them.
        for (const auto& [key, value] : r.items()) {
            const session::FrameOptionField* field = session::frameOptionByKey(key);
            if (!field || !(field->uses & session::kUseStudy)) {
                std::string known;
                for (const session::FrameOptionField& f : session::frameOptionFields())
                    if (f.uses & session::kUseStudy) known += (known.empty() ? "" : ", ") + f.key;
                throw InputError(where, "render." + key + ": unknown key (known: " + known + ")");
            }
        }
        for (const auto& [key, value] : r.items()) study.render.setFromJson(key, value, where, "render.");
        try {
            if (study.render.backend == "rtcore") study.render.validate();
            study.render.planOptions();
            if (study.render.denoises()) study.render.denoiseList();
        } catch (const InputError& e) {
            throw InputError(where, asStudyKey(e.what()));
        }
    }

    // Step: the parameter space.
    if (j.contains("base")) study.base = parseOverrideObject(j.at("base"), where, "base");
    if (j.contains("grid")) {
        const json& g = j.at("grid");
        if (!g.is_object()) throw InputError(where, "grid: must be an object {\"section.field\": [values...]}");
        for (const auto& [key, values] : g.items()) {
            const std::string path = "grid." + key;
            if (!values.is_array() || values.empty())
                throw InputError(where, path + ": must be a non-empty list of values");
            std::set<std::string> seen;
            for (const json& v : values) {
                checkScalar(v, where, path);
                rtcore_sim::RtCoreConfig scratch;
                scratch.set(Override{key, v}.assignment(), where + ": grid");
                if (!seen.insert(v.dump()).second) throw InputError(where, path + ": value " + v.dump() + " repeated");
            }
            study.grid.emplace_back(key, std::vector<json>(values.begin(), values.end()));
        }
    }
    if (j.contains("list")) {
        const json& l = j.at("list");
        if (!l.is_array()) throw InputError(where, "list: must be a list of override objects");
        for (std::size_t i = 0; i < l.size(); ++i) {
            const std::string path = "list[" + std::to_string(i) + "]";
            if (l[i].is_object() && l[i].empty()) throw InputError(where, path + ": empty override set");
            study.list.push_back(parseOverrideObject(l[i], where, path));
        }
    }
    // Step: the number of points, capped before anything is expanded.
    std::uint64_t sets = study.grid.empty() ? 0 : 1;
    for (const auto& [key, values] : study.grid)
        sets = std::min<std::uint64_t>(sets * values.size(), kMaxStudyPoints + 1);
    sets += study.list.size();
    const std::uint64_t points = std::max<std::uint64_t>(sets, 1) * study.workloads.size();
    if (points > kMaxStudyPoints)
        throw InputError(where,
                         "the study has " +
                             (sets > kMaxStudyPoints ? std::string("more than ") + std::to_string(kMaxStudyPoints)
                                                     : std::to_string(points)) +
                             " points (workloads x override sets); at most " + std::to_string(kMaxStudyPoints) +
                             " (split it into several studies)");
    const bool overrides =
        !study.base.empty() || !study.grid.empty() || !study.list.empty() || !study.render.rtcoreConfig.empty();
    if (overrides && study.render.backend != "rtcore")
        throw InputError(where,
                         "render.backend: RT-core parameters (base, grid, list, rtcoreConfig) need "
                         "\"rtcore\" (got \"" +
                             study.render.backend + "\")");

    // Step: every point's whole configuration, checked now rather than mid-sweep.
    if (checkPoints && study.render.backend == "rtcore")
        for (const Point& p : expandPoints(study)) resolveConfig(study, &p, where);
    return study;
}

Study loadStudy(const std::filesystem::path& path) {
    const std::string where = path.string();
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(where, "cannot open study file");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (jsonNestingDepth(text) > kMaxJsonNesting)
        throw InputError(where, "JSON nested deeper than " + std::to_string(kMaxJsonNesting) + " levels");
    json j;
    try {
        j = json::parse(text);
    } catch (const json::exception& e) {  // parse_error, and out_of_range for numbers like 1e999
        throw InputError(where, std::string("not valid JSON: ") + e.what());
    }
    return parseStudy(j, where);
}

std::vector<Point> expandPoints(const Study& study) {
    // Step: the override sets: the grid's product (last key fastest), then the list.
    std::vector<OverrideSet> sets;
    if (!study.grid.empty()) {
        std::vector<std::size_t> digit(study.grid.size(), 0);
        for (;;) {
            OverrideSet set;
            for (std::size_t k = 0; k < study.grid.size(); ++k)
                set.push_back({study.grid[k].first, study.grid[k].second[digit[k]]});
            sets.push_back(std::move(set));
            std::size_t k = study.grid.size();
            while (k > 0 && ++digit[k - 1] == study.grid[k - 1].second.size()) digit[--k] = 0;
            if (k == 0) break;
        }
    }
    for (const OverrideSet& set : study.list) sets.push_back(set);
    if (sets.empty()) sets.emplace_back();  // one point per workload: the base configuration

    // Step: workloads x sets.
    std::vector<Point> points;
    for (const Workload& w : study.workloads)
        for (const OverrideSet& set : sets) {
            Point p;
            p.index = points.size();
            char id[24];
            std::snprintf(id, sizeof id, "p%04zu", p.index);
            p.id = id;
            p.workload = w;
            p.overrides = set;
            points.push_back(std::move(p));
        }
    return points;
}

std::vector<std::string> sweptParameters(const Study& study) {
    std::vector<std::string> keys;
    const auto add = [&](const std::string& key) {
        for (const std::string& k : keys)
            if (k == key) return;
        keys.push_back(key);
    };
    for (const auto& [key, values] : study.grid) add(key);
    for (const OverrideSet& set : study.list)
        for (const Override& o : set) add(o.key);
    return keys;
}

json overrideValue(const Point& point, const std::string& key) {
    for (const Override& o : point.overrides)
        if (o.key == key) return o.value;
    return nullptr;
}

rtcore_sim::RtCoreConfig resolveConfig(const Study& study, const Point* point, const std::string& where) {
    rtcore_sim::RtCoreConfig config;
    try {
        config = rtcore_sim::RtCoreConfig::load(study.render.rtcoreConfig);
    } catch (const InputError& e) {
        throw InputError(where, std::string("render.rtcoreConfig: ") + e.what());
    }
    for (const Override& o : study.base) config.set(o.assignment(), where + ": base");
    if (!point) {
        config.validate(where + ": base");
        config.checkExplicitKeys(where + ": base");
        return config;
    }
    std::string label = "point " + point->id + " (" + point->workload.label();
    for (const Override& o : point->overrides) label += ", " + o.assignment();
    label += ")";
    for (const Override& o : point->overrides) config.set(o.assignment(), where + ": " + label);
    config.validate(where + ": " + label);
    config.checkExplicitKeys(where + ": " + label);  // refused before anything runs, naming the point
    return config;
}

std::vector<std::string> renderArguments(const Study& study, const Point& point, const std::string& outDir,
                                         int threads) {
    const session::FrameOptions& s = study.render;
    // Step: a ray-trace workload replays its recorded rays (traversal only); a
    // scene renders with every render option that differs from rtlab render's default.
    std::vector<std::string> a;
    if (!point.workload.rays.empty()) {
        a = {"replay", "--scene", point.workload.scene, "--rays", point.workload.rays, "--backend", s.backend};
    } else {
        a = {"render", "--scene", point.workload.scene};
        if (!point.workload.camera.empty()) a.insert(a.end(), {"--camera", point.workload.camera});
        session::FrameOptions render = s;
        render.rtcoreConfig.clear();  // added below, for both
        render.threads = 0;           // added below: the sweep's choice
        const std::vector<std::string> options = render.toArgs(session::kUseStudy);
        a.insert(a.end(), options.begin(), options.end());
    }
    // Step: the RT-core configuration and the output, the same for both.
    if (!s.rtcoreConfig.empty()) a.insert(a.end(), {"--rtcore-config", s.rtcoreConfig});
    for (const Override& o : study.base) a.insert(a.end(), {"--rtcore-set", o.assignment()});
    for (const Override& o : point.overrides) a.insert(a.end(), {"--rtcore-set", o.assignment()});
    if (threads > 0) a.insert(a.end(), {"--threads", std::to_string(threads)});
    a.insert(a.end(), {"--out", outDir});
    return a;
}

std::string shellCommand(const std::vector<std::string>& arguments) {
    std::string line;
    for (const std::string& arg : arguments) {
        const bool plain = !arg.empty() && arg.find_first_not_of(
                                               "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                               "0123456789-_./:=,+@%") == std::string::npos;
        if (!line.empty()) line += ' ';
        if (plain) {
            line += arg;
        } else {
            line += '\'';
            for (char c : arg) line += c == '\'' ? std::string("'\\''") : std::string(1, c);
            line += '\'';
        }
    }
    return line;
}

}  // namespace rtlab::study
