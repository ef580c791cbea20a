// Scene description JSON (docs/scene-format.md): references glTF files and
// volumes, adds lights, a camera and a camera path.
//
// Two phases: the whole document is parsed and validated into plain
// descriptions first (types, ranges, unknown keys, referenced files exist), so
// a typo is reported before any slow glTF or VDB load; then the World is
// built. Every problem of the JSON itself is an InputError naming the JSON
// file and the key path ("lights[1].intensity: must be >= 0"); errors of the
// referenced files come from their loaders and name those files.
#include <rtlab/core/error.hpp>
#include <rtlab/core/json_nesting.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace rtlab::ecs::load {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// ---- descriptions (phase 1 output) -------------------------------------------

struct GltfDesc {
    std::string keyPath;  // "gltf[i]", naming the entry in its file's errors
    fs::path file;
    std::string name;
    vec3 translation{0.f};
    quat rotation{1.f, 0.f, 0.f, 0.f};
    vec3 scale{1.f};
};

struct VolumeDesc {
    std::string keyPath;  // "volumes[i]", for errors of the procedural builder
    std::string name;
    bool procedural = false;
    fs::path file;         // .vdb form
    std::string gridName;  // .vdb form; "" = first float grid
    Aabb bounds;           // procedural form
    float voxelSize = 0.f;
    float density = 1.f;
    std::uint32_t seed = 0;
    Volume volume;
    vec3 translation{0.f};
};

struct LightDesc {
    std::string name;
    Light light;
    vec3 position{0.f};
    quat rotation{1.f, 0.f, 0.f, 0.f};
};

struct Pose {
    vec3 position{0.f};
    quat rotation{1.f, 0.f, 0.f, 0.f};
};

struct PathKey {
    float time = 0.f;
    Pose pose;
};

struct CameraDesc {
    std::string name = "camera";
    Camera camera;
    std::optional<Pose> pose;  // absent: the first camera-path key
};

struct SceneDesc {
    SceneSettings settings;
    std::vector<GltfDesc> gltfs;
    std::vector<VolumeDesc> volumes;
    std::vector<LightDesc> lights;
    std::optional<CameraDesc> camera;
    std::vector<PathKey> cameraPath;
};

// ---- validation helpers -----------------------------------------------------

std::string joinKey(const std::string& parent, const std::string& key) {
    return parent.empty() ? key : parent + "." + key;
}
std::string joinIndex(const std::string& parent, std::size_t i) { return parent + "[" + std::to_string(i) + "]"; }

class Parser {
public:
    explicit Parser(const fs::path& jsonPath) : jsonPath_(jsonPath), folder_(jsonPath.parent_path()) {}

    [[noreturn]] void fail(const std::string& keyPath, const std::string& problem) const {
        throw InputError(jsonPath_.string(), (keyPath.empty() ? std::string("(root)") : keyPath) + ": " + problem);
    }

    // An object whose keys all belong to `allowed`.
    void expectObject(const json& j, const std::string& keyPath,
                      std::initializer_list<std::string_view> allowed) const {
        if (!j.is_object()) fail(keyPath, std::string("expected an object, got ") + j.type_name());
        for (const auto& item : j.items()) {
            bool known = false;
            for (std::string_view k : allowed) known = known || item.key() == k;
            if (!known) {
                std::string list;
                for (std::string_view k : allowed) list += (list.empty() ? "" : ", ") + std::string(k);
                fail(joinKey(keyPath, item.key()), "unknown key (allowed here: " + list + ")");
            }
        }
    }

    const json& expectArray(const json& j, const std::string& keyPath) const {
        if (!j.is_array()) fail(keyPath, std::string("expected an array, got ") + j.type_name());
        return j;
    }

    float number(const json& j, const std::string& keyPath) const {
        if (!j.is_number()) fail(keyPath, std::string("expected a number, got ") + j.type_name());
        const double d = j.get<double>();
        if (!std::isfinite(d)) fail(keyPath, "not a finite number");
        const float f = static_cast<float>(d);
        if (!std::isfinite(f)) fail(keyPath, "number out of range (beyond 32-bit float)");
        return f;
    }

    std::uint32_t uint32(const json& j, const std::string& keyPath) const {
        if (j.is_number_unsigned()) {
            const auto v = j.get<std::uint64_t>();
            if (v <= 0xffffffffull) return static_cast<std::uint32_t>(v);
        }
        fail(keyPath, "expected an integer in [0, 4294967295], got " + describe(j));
    }

    std::string string(const json& j, const std::string& keyPath) const {
        if (!j.is_string()) fail(keyPath, std::string("expected a string, got ") + j.type_name());
        return j.get<std::string>();
    }

    template <std::size_t N>
    std::array<float, N> numbers(const json& j, const std::string& keyPath) const {
        if (!j.is_array() || j.size() != N)
            fail(keyPath, "expected an array of " + std::to_string(N) + " numbers, got " + describe(j));
        std::array<float, N> out{};
        for (std::size_t i = 0; i < N; ++i) out[i] = number(j[i], joinIndex(keyPath, i));
        return out;
    }
    vec2 vec2Of(const json& j, const std::string& keyPath) const {
        const auto a = numbers<2>(j, keyPath);
        return {a[0], a[1]};
    }
    vec3 vec3Of(const json& j, const std::string& keyPath) const {
        const auto a = numbers<3>(j, keyPath);
        return {a[0], a[1], a[2]};
    }
    // [x, y, z, w], normalised; a zero quaternion is an error.
    quat quatOf(const json& j, const std::string& keyPath) const {
        const auto a = numbers<4>(j, keyPath);
        const quat q(a[3], a[0], a[1], a[2]);
        const float len = glm::length(q);
        if (!(len > 1e-6f) || !std::isfinite(len)) fail(keyPath, "not a rotation (zero-length quaternion)");
        return q / len;
    }

    // A referenced file, relative to the JSON file's folder; must exist.
    fs::path file(const json& j, const std::string& keyPath) const {
        const std::string s = string(j, keyPath);
        if (s.empty()) fail(keyPath, "empty file name");
        const fs::path p(s);
        const fs::path resolved = p.is_absolute() ? p : folder_ / p;
        std::error_code ec;
        if (!fs::exists(resolved, ec)) fail(keyPath, "no such file '" + resolved.string() + "'");
        if (fs::is_directory(resolved, ec)) fail(keyPath, "'" + resolved.string() + "' is a directory, not a file");
        return resolved;
    }

    // Range checks.
    float nonNegative(float v, const std::string& keyPath) const {
        if (v < 0.f) fail(keyPath, "must be >= 0, got " + formatFloat(v));
        return v;
    }
    float positive(float v, const std::string& keyPath) const {
        if (!(v > 0.f)) fail(keyPath, "must be > 0, got " + formatFloat(v));
        return v;
    }
    vec3 nonNegative(const vec3& v, const std::string& keyPath) const {
        for (int i = 0; i < 3; ++i) nonNegative(v[i], joinIndex(keyPath, static_cast<std::size_t>(i)));
        return v;
    }
    vec3 unitRange(const vec3& v, const std::string& keyPath) const {
        for (int i = 0; i < 3; ++i)
            if (v[i] < 0.f || v[i] > 1.f)
                fail(joinIndex(keyPath, static_cast<std::size_t>(i)), "must be in [0, 1], got " + formatFloat(v[i]));
        return v;
    }

    // Rotation turning local -Z towards `direction` (from "direction" or
    // "lookAt" minus `position`); `fallback` when neither key is present.
    quat orientation(const json& obj, const std::string& keyPath, const vec3& position, const vec3& fallback) const {
        const bool hasDirection = obj.contains("direction"), hasLookAt = obj.contains("lookAt");
        if (hasDirection && hasLookAt) fail(keyPath, "give either 'direction' or 'lookAt', not both");
        vec3 dir = fallback;
        std::string where = keyPath;
        if (hasDirection) {
            where = joinKey(keyPath, "direction");
            dir = vec3Of(obj["direction"], where);
        } else if (hasLookAt) {
            where = joinKey(keyPath, "lookAt");
            dir = vec3Of(obj["lookAt"], where) - position;
        }
        const float len = glm::length(dir);
        if (!(len > 1e-6f) || !std::isfinite(len))
            fail(where, hasLookAt ? "lookAt must differ from the position"
                                  : "direction must be a non-zero vector of finite length");
        return orientationLookingAlong(dir / len);
    }

    static std::string formatFloat(float v) {
        std::ostringstream os;
        os << v;
        return os.str();
    }
    static std::string describe(const json& j) {
        std::string s = j.dump();
        if (s.size() > 40) s = s.substr(0, 37) + "...";
        return s;
    }

    const fs::path& jsonPath() const { return jsonPath_; }

private:
    fs::path jsonPath_;
    fs::path folder_;
};

// ---- reading and parsing ----------------------------------------------------

std::string readFile(const fs::path& path) {
    std::error_code ec;
    if (!fs::exists(path, ec)) throw InputError(path.string(), "no such file");
    if (fs::is_directory(path, ec)) throw InputError(path.string(), "is a directory, not a scene file");
    if (!fs::is_regular_file(path, ec)) throw InputError(path.string(), "not a regular file");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path.string(), "cannot open for reading");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) throw InputError(path.string(), "read error");
    return text;
}

// "[json.exception.parse_error.101] parse error at ..." -> "parse error at ...".
std::string stripNlohmannPrefix(const std::string& what) {
    if (what.rfind("[json.exception.", 0) == 0) {
        const std::size_t close = what.find("] ");
        if (close != std::string::npos) return what.substr(close + 2);
    }
    return what;
}

// Bounds on what a short file can ask for: models loaded and volumes built
// (a procedural fog of 2^25 voxels takes seconds, from a line of text).
constexpr std::size_t kMaxGltfEntries = 1024;
constexpr std::size_t kMaxVolumeEntries = 16;

// Parses the text; duplicate keys (which nlohmann would silently collapse)
// are errors, reported with their key path.
json parseDocument(const std::string& text, const Parser& p) {
    struct Frame {
        bool isArray = false;
        std::size_t nextIndex = 0;
        std::string lastKey;
        std::set<std::string> keys;
        std::string path;
    };
    std::vector<Frame> stack;
    std::optional<std::string> duplicate;
    // Key path of the value that starts now (advances array indices).
    auto valuePath = [&]() -> std::string {
        if (stack.empty()) return "";
        Frame& top = stack.back();
        if (top.isArray) return joinIndex(top.path, top.nextIndex++);
        return joinKey(top.path, top.lastKey);
    };
    const json::parser_callback_t callback = [&](int, json::parse_event_t event, json& parsed) {
        switch (event) {
            case json::parse_event_t::object_start:
            case json::parse_event_t::array_start: {
                Frame f;
                f.isArray = event == json::parse_event_t::array_start;
                f.path = valuePath();
                stack.push_back(std::move(f));
                break;
            }
            case json::parse_event_t::object_end:
            case json::parse_event_t::array_end:
                if (!stack.empty()) stack.pop_back();
                break;
            case json::parse_event_t::key:
                if (!stack.empty() && parsed.is_string()) {
                    Frame& top = stack.back();
                    top.lastKey = parsed.get<std::string>();
                    if (!top.keys.insert(top.lastKey).second && !duplicate) duplicate = joinKey(top.path, top.lastKey);
                }
                break;
            case json::parse_event_t::value: valuePath(); break;
        }
        return true;
    };
    json doc;
    try {
        doc = json::parse(text, callback, /*allow_exceptions=*/true, /*ignore_comments=*/false);
    } catch (const json::parse_error& e) {
        throw InputError(p.jsonPath().string(),
                         "invalid JSON at byte " + std::to_string(e.byte) + ": " + stripNlohmannPrefix(e.what()));
    } catch (const json::exception& e) {
        // e.g. out_of_range.406 "number overflow parsing '1e999'".
        throw InputError(p.jsonPath().string(), "invalid JSON: " + stripNlohmannPrefix(e.what()));
    }
    if (duplicate) p.fail(*duplicate, "duplicate key");
    return doc;
}

GltfDesc parseGltf(const Parser& p, const json& j, const std::string& kp) {
    p.expectObject(j, kp, {"file", "name", "translation", "rotation", "scale"});
    GltfDesc d;
    d.keyPath = kp;
    if (!j.contains("file")) p.fail(joinKey(kp, "file"), "required");
    d.file = p.file(j["file"], joinKey(kp, "file"));
    d.name = j.contains("name") ? p.string(j["name"], joinKey(kp, "name")) : d.file.stem().string();
    if (j.contains("translation")) d.translation = p.vec3Of(j["translation"], joinKey(kp, "translation"));
    if (j.contains("rotation")) d.rotation = p.quatOf(j["rotation"], joinKey(kp, "rotation"));
    if (j.contains("scale")) {
        d.scale = p.vec3Of(j["scale"], joinKey(kp, "scale"));
        for (int i = 0; i < 3; ++i)
            if (d.scale[i] == 0.f)
                p.fail(joinIndex(joinKey(kp, "scale"), static_cast<std::size_t>(i)), "must be non-zero");
    }
    return d;
}

VolumeDesc parseVolume(const Parser& p, const json& j, const std::string& kp, std::size_t index) {
    if (!j.is_object()) p.fail(kp, std::string("expected an object, got ") + j.type_name());
    VolumeDesc d;
    d.keyPath = kp;
    const bool hasFile = j.contains("file"), hasProcedural = j.contains("procedural");
    if (hasFile == hasProcedural) p.fail(kp, "give exactly one of 'file' (a .vdb) or 'procedural'");
    if (hasFile) {
        p.expectObject(j, kp, {"file", "grid", "name", "densityScale", "albedo", "translation"});
        d.file = p.file(j["file"], joinKey(kp, "file"));
        if (j.contains("grid")) d.gridName = p.string(j["grid"], joinKey(kp, "grid"));
        d.name = d.file.stem().string();
    } else {
        p.expectObject(
            j, kp,
            {"procedural", "bounds", "voxelSize", "density", "seed", "name", "densityScale", "albedo", "translation"});
        d.procedural = true;
        const std::string kind = p.string(j["procedural"], joinKey(kp, "procedural"));
        if (kind != "fog") p.fail(joinKey(kp, "procedural"), "unknown procedural volume '" + kind + "' (known: fog)");
        const std::string bk = joinKey(kp, "bounds");
        if (!j.contains("bounds")) p.fail(bk, "required");
        const json& b = j["bounds"];
        if (!b.is_array() || b.size() != 2)
            p.fail(bk, "expected [[xmin, ymin, zmin], [xmax, ymax, zmax]], got " + Parser::describe(b));
        d.bounds.lo = p.vec3Of(b[0], joinIndex(bk, 0));
        d.bounds.hi = p.vec3Of(b[1], joinIndex(bk, 1));
        for (int a = 0; a < 3; ++a)
            if (!(d.bounds.lo[a] < d.bounds.hi[a]))
                p.fail(bk, "min must be < max on every axis (axis " + std::string(1, "xyz"[a]) + ": " +
                               Parser::formatFloat(d.bounds.lo[a]) + " >= " + Parser::formatFloat(d.bounds.hi[a]) +
                               ")");
        const vec3 e = d.bounds.extent();
        d.voxelSize = j.contains("voxelSize")
                          ? p.positive(p.number(j["voxelSize"], joinKey(kp, "voxelSize")), joinKey(kp, "voxelSize"))
                          : std::max(e.x, std::max(e.y, e.z)) / 64.f;
        if (j.contains("density"))
            d.density = p.nonNegative(p.number(j["density"], joinKey(kp, "density")), joinKey(kp, "density"));
        if (j.contains("seed")) d.seed = p.uint32(j["seed"], joinKey(kp, "seed"));
        d.name = "fog " + std::to_string(index);
    }
    if (j.contains("name")) d.name = p.string(j["name"], joinKey(kp, "name"));
    if (j.contains("densityScale"))
        d.volume.densityScale =
            p.nonNegative(p.number(j["densityScale"], joinKey(kp, "densityScale")), joinKey(kp, "densityScale"));
    if (j.contains("albedo"))
        d.volume.albedo = p.unitRange(p.vec3Of(j["albedo"], joinKey(kp, "albedo")), joinKey(kp, "albedo"));
    if (j.contains("translation")) d.translation = p.vec3Of(j["translation"], joinKey(kp, "translation"));
    return d;
}

LightDesc parseLight(const Parser& p, const json& j, const std::string& kp, std::size_t index) {
    if (!j.is_object()) p.fail(kp, std::string("expected an object, got ") + j.type_name());
    const std::string tk = joinKey(kp, "type");
    if (!j.contains("type")) p.fail(tk, "required (point, spot, directional, rect or sphere)");
    const std::string type = p.string(j["type"], tk);
    LightDesc d;
    if (type == "point") {
        p.expectObject(j, kp, {"type", "name", "color", "intensity", "position", "range"});
        d.light.type = LightType::Point;
    } else if (type == "spot") {
        p.expectObject(j, kp,
                       {"type", "name", "color", "intensity", "position", "range", "direction", "lookAt",
                        "innerConeAngle", "outerConeAngle"});
        d.light.type = LightType::Spot;
    } else if (type == "directional") {
        p.expectObject(j, kp, {"type", "name", "color", "intensity", "position", "direction", "lookAt"});
        d.light.type = LightType::Directional;
    } else if (type == "rect") {
        p.expectObject(j, kp, {"type", "name", "color", "intensity", "position", "direction", "lookAt", "size"});
        d.light.type = LightType::Rect;
    } else if (type == "sphere") {
        p.expectObject(j, kp, {"type", "name", "color", "intensity", "position", "radius"});
        d.light.type = LightType::Sphere;
    } else {
        p.fail(tk, "unknown light type '" + type + "' (known: point, spot, directional, rect, sphere)");
    }
    d.name = j.contains("name") ? p.string(j["name"], joinKey(kp, "name")) : type + " light " + std::to_string(index);
    if (j.contains("color"))
        d.light.color = p.nonNegative(p.vec3Of(j["color"], joinKey(kp, "color")), joinKey(kp, "color"));
    if (j.contains("intensity"))
        d.light.intensity = p.nonNegative(p.number(j["intensity"], joinKey(kp, "intensity")), joinKey(kp, "intensity"));
    if (j.contains("position")) d.position = p.vec3Of(j["position"], joinKey(kp, "position"));
    if (j.contains("range"))
        d.light.range = p.nonNegative(p.number(j["range"], joinKey(kp, "range")), joinKey(kp, "range"));
    if (d.light.type == LightType::Spot) {
        if (j.contains("innerConeAngle"))
            d.light.innerConeAngle = p.nonNegative(p.number(j["innerConeAngle"], joinKey(kp, "innerConeAngle")),
                                                   joinKey(kp, "innerConeAngle"));
        if (j.contains("outerConeAngle"))
            d.light.outerConeAngle =
                p.positive(p.number(j["outerConeAngle"], joinKey(kp, "outerConeAngle")), joinKey(kp, "outerConeAngle"));
        if (d.light.outerConeAngle > 0.5f * kPi)
            p.fail(joinKey(kp, "outerConeAngle"),
                   "must be <= pi/2, got " + Parser::formatFloat(d.light.outerConeAngle));
        if (d.light.innerConeAngle > d.light.outerConeAngle)
            p.fail(joinKey(kp, "innerConeAngle"), "must be <= outerConeAngle");
    }
    if (d.light.type == LightType::Rect && j.contains("size")) {
        const std::string sk = joinKey(kp, "size");
        d.light.size = p.vec2Of(j["size"], sk);
        p.positive(d.light.size.x, joinIndex(sk, 0));
        p.positive(d.light.size.y, joinIndex(sk, 1));
    }
    if (d.light.type == LightType::Sphere) {
        if (!j.contains("radius")) p.fail(joinKey(kp, "radius"), "required for a sphere light");
        d.light.radius = p.positive(p.number(j["radius"], joinKey(kp, "radius")), joinKey(kp, "radius"));
    }
    if (d.light.type == LightType::Spot || d.light.type == LightType::Directional || d.light.type == LightType::Rect)
        d.rotation = p.orientation(j, kp, d.position, vec3(0.f, -1.f, 0.f));
    return d;
}

Pose parsePose(const Parser& p, const json& j, const std::string& kp) {
    Pose pose;
    const std::string pk = joinKey(kp, "position"), lk = joinKey(kp, "lookAt");
    if (!j.contains("position")) p.fail(pk, "required");
    if (!j.contains("lookAt")) p.fail(lk, "required");
    pose.position = p.vec3Of(j["position"], pk);
    pose.rotation = p.orientation(j, kp, pose.position, vec3(0.f, 0.f, -1.f));
    return pose;
}

CameraDesc parseCamera(const Parser& p, const json& j, const std::string& kp, bool hasPath) {
    p.expectObject(j, kp, {"name", "position", "lookAt", "yfov", "znear", "zfar", "aspectRatio"});
    CameraDesc d;
    if (j.contains("name")) d.name = p.string(j["name"], joinKey(kp, "name"));
    const bool hasPosition = j.contains("position"), hasLookAt = j.contains("lookAt");
    if (hasPosition || hasLookAt || !hasPath) {
        if (!hasPath && !hasPosition && !hasLookAt)
            p.fail(kp, "needs 'position' and 'lookAt' (they may be left out only when a cameraPath is given)");
        d.pose = parsePose(p, j, kp);
    }
    if (j.contains("yfov")) {
        d.camera.yfov = p.number(j["yfov"], joinKey(kp, "yfov"));
        if (!(d.camera.yfov > 0.f && d.camera.yfov < kPi))
            p.fail(joinKey(kp, "yfov"), "must be in (0, pi) radians, got " + Parser::formatFloat(d.camera.yfov));
    }
    if (j.contains("znear"))
        d.camera.znear = p.positive(p.number(j["znear"], joinKey(kp, "znear")), joinKey(kp, "znear"));
    if (j.contains("zfar")) d.camera.zfar = p.number(j["zfar"], joinKey(kp, "zfar"));
    if (!(d.camera.zfar > d.camera.znear))
        p.fail(joinKey(kp, "zfar"), "must be > znear (" + Parser::formatFloat(d.camera.znear) + "), got " +
                                        Parser::formatFloat(d.camera.zfar));
    if (j.contains("aspectRatio"))
        d.camera.aspectRatio =
            p.nonNegative(p.number(j["aspectRatio"], joinKey(kp, "aspectRatio")), joinKey(kp, "aspectRatio"));
    return d;
}

std::vector<PathKey> parseCameraPath(const Parser& p, const json& j, const std::string& kp) {
    p.expectArray(j, kp);
    if (j.size() < 2) p.fail(kp, "needs at least 2 keys, got " + std::to_string(j.size()));
    std::vector<PathKey> keys;
    for (std::size_t i = 0; i < j.size(); ++i) {
        const std::string ik = joinIndex(kp, i);
        p.expectObject(j[i], ik, {"time", "position", "lookAt"});
        PathKey k;
        if (!j[i].contains("time")) p.fail(joinKey(ik, "time"), "required");
        k.time = p.nonNegative(p.number(j[i]["time"], joinKey(ik, "time")), joinKey(ik, "time"));
        if (!keys.empty() && !(k.time > keys.back().time))
            p.fail(joinKey(ik, "time"), "times must be strictly increasing (" + Parser::formatFloat(k.time) +
                                            " after " + Parser::formatFloat(keys.back().time) + ")");
        k.pose = parsePose(p, j[i], ik);
        keys.push_back(k);
    }
    return keys;
}

SceneDesc parseScene(const Parser& p, const json& doc) {
    p.expectObject(doc, "",
                   {"name", "frameSeconds", "background", "gltf", "volumes", "lights", "camera", "cameraPath"});
    SceneDesc s;
    s.settings.name = doc.contains("name") ? p.string(doc["name"], "name") : p.jsonPath().stem().string();
    if (doc.contains("frameSeconds"))
        s.settings.frameSeconds = p.positive(p.number(doc["frameSeconds"], "frameSeconds"), "frameSeconds");
    if (doc.contains("background"))
        s.settings.backgroundRadiance = p.nonNegative(p.vec3Of(doc["background"], "background"), "background");
    if (doc.contains("gltf")) {
        const json& a = p.expectArray(doc["gltf"], "gltf");
        if (a.size() > kMaxGltfEntries)
            p.fail("gltf", "more than " + std::to_string(kMaxGltfEntries) +
                               " models (each is loaded: a short entry can cost seconds)");
        for (std::size_t i = 0; i < a.size(); ++i) s.gltfs.push_back(parseGltf(p, a[i], joinIndex("gltf", i)));
    }
    if (doc.contains("volumes")) {
        const json& a = p.expectArray(doc["volumes"], "volumes");
        if (a.size() > kMaxVolumeEntries)
            p.fail("volumes", "more than " + std::to_string(kMaxVolumeEntries) +
                                  " volumes (each is built or read: a short entry can cost seconds)");
        for (std::size_t i = 0; i < a.size(); ++i)
            s.volumes.push_back(parseVolume(p, a[i], joinIndex("volumes", i), i));
    }
    if (doc.contains("lights")) {
        const json& a = p.expectArray(doc["lights"], "lights");
        for (std::size_t i = 0; i < a.size(); ++i) s.lights.push_back(parseLight(p, a[i], joinIndex("lights", i), i));
    }
    const bool hasPath = doc.contains("cameraPath");
    if (hasPath) s.cameraPath = parseCameraPath(p, doc["cameraPath"], "cameraPath");
    if (doc.contains("camera")) s.camera = parseCamera(p, doc["camera"], "camera", hasPath);
    else if (hasPath) s.camera = CameraDesc{};  // default lens, posed by the path
    return s;
}

// ---- building (phase 2) -------------------------------------------------------

void build(World& world, const Parser& p, const SceneDesc& s) {
    world.settings() = s.settings;

    DecodeBudget budget;  // one for the whole scene: 1024 entries naming one small file get one allowance
    for (const GltfDesc& g : s.gltfs) {
        const Entity parent = world.create(g.name);
        world.emplace(parent, LocalTransform{g.translation, g.rotation, g.scale});
        try {
            loadGltf(world, g.file, parent, &budget);
        } catch (const InputError& e) {
            // The entry, then the glTF file's own error (which names the file):
            // a budget the entries share may run out in a file that alone is small.
            p.fail(g.keyPath, e.what());
        }
    }

    std::uint64_t fogVoxels = 0;  // all procedural fogs together, checked before any is built
    for (const VolumeDesc& v : s.volumes) {
        const std::uint64_t voxels = v.procedural ? VolumeGrid::proceduralFogVoxels(v.bounds, v.voxelSize) : 0;
        if (voxels > VolumeGrid::kMaxProceduralVoxels) continue;  // too many alone: makeProceduralFog says so
        if ((fogVoxels += voxels) > VolumeGrid::kMaxProceduralVoxels)
            p.fail(v.keyPath, "the procedural fogs need more than " + std::to_string(VolumeGrid::kMaxProceduralVoxels) +
                                  " voxels in all");
    }
    for (const VolumeDesc& v : s.volumes) {
        std::shared_ptr<VolumeGrid> grid;
        if (v.procedural) {
            try {
                grid = VolumeGrid::makeProceduralFog(v.bounds, v.voxelSize, v.density, v.seed);
            } catch (const std::invalid_argument& e) {
                p.fail(v.keyPath, e.what());  // e.g. too many voxels for bounds / voxelSize
            }
        } else {
            grid = VolumeGrid::loadVdb(v.file, v.gridName);  // InputError naming the .vdb propagates
        }
        Volume volume = v.volume;
        volume.grid = world.addVolumeGrid(std::move(grid));
        const Entity e = world.create(v.name);
        world.emplace(e, LocalTransform{v.translation, quat(1.f, 0.f, 0.f, 0.f), vec3(1.f)});
        world.emplace(e, volume);
    }

    for (const LightDesc& l : s.lights) {
        const Entity e = world.create(l.name);
        world.emplace(e, LocalTransform{l.position, l.rotation, vec3(1.f)});
        world.emplace(e, l.light);
    }

    if (s.camera) {
        const Pose pose = s.camera->pose ? *s.camera->pose : s.cameraPath.front().pose;
        const Entity cam = world.create(s.camera->name);
        world.emplace(cam, LocalTransform{pose.position, pose.rotation, vec3(1.f)});
        world.emplace(cam, s.camera->camera);
        world.setActiveCamera(cam);

        if (!s.cameraPath.empty()) {
            AnimationChannel translation, rotation;
            translation.target = rotation.target = cam;
            translation.path = AnimationPath::Translation;
            rotation.path = AnimationPath::Rotation;
            translation.interpolation = rotation.interpolation = Interpolation::Linear;
            translation.componentsPerKey = 3;
            rotation.componentsPerKey = 4;
            quat previous(1.f, 0.f, 0.f, 0.f);
            for (std::size_t i = 0; i < s.cameraPath.size(); ++i) {
                const PathKey& k = s.cameraPath[i];
                translation.times.push_back(k.time);
                rotation.times.push_back(k.time);
                translation.values.insert(translation.values.end(),
                                          {k.pose.position.x, k.pose.position.y, k.pose.position.z});
                // Keep consecutive keys in one hemisphere: shortest-arc blending.
                quat q = k.pose.rotation;
                if (i > 0 && glm::dot(previous, q) < 0.f) q = -q;
                previous = q;
                rotation.values.insert(rotation.values.end(), {q.x, q.y, q.z, q.w});
            }
            AnimationClip clip;
            clip.name = "cameraPath";
            clip.channels.push_back(std::move(translation));
            clip.channels.push_back(std::move(rotation));
            world.addAnimation(std::move(clip));
        }
    }
}

}  // namespace

void loadSceneJson(World& world, const std::filesystem::path& path) {
    const Parser parser(path);
    const std::string text = readFile(path);
    if (jsonNestingDepth(text) > kMaxJsonNesting)
        throw InputError(path.string(), "JSON nested deeper than " + std::to_string(kMaxJsonNesting) + " levels");
    const json doc = parseDocument(text, parser);
    SceneDesc scene;
    try {
        scene = parseScene(parser, doc);
    } catch (const json::exception& e) {
        // The helpers check types before every access, so this is a safety net
        // that still names the file instead of escaping as an internal error.
        throw InputError(path.string(), "invalid scene: " + stripNlohmannPrefix(e.what()));
    }
    build(world, parser, scene);
}

}  // namespace rtlab::ecs::load
