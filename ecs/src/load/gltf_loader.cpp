// glTF 2.0 loader (.gltf / .glb) on top of tinygltf. This is the only
// translation unit that includes tiny_gltf.h (tinygltf is a shared library
// here: TINYGLTF_IMPLEMENTATION must not be defined).
//
// The loader works in four stages, and the World is touched only in the last:
//   1. Structural pre-check of the raw JSON (nlohmann::json): property types,
//      nesting depth, GLB container layout, bufferView/buffer extents,
//      extensionsRequired. tinygltf 2.7 is lenient about wrong JSON types
//      (it silently falls back to defaults) and trusts some offsets, so this
//      check runs before tinygltf sees the file.
//   2. tinygltf parse (buffers, images). Any tinygltf error is an InputError;
//      warnings are ignored.
//   3. Semantic validation and conversion into staging structures: every
//      index, accessor extent, component type, index value, float value and
//      the node hierarchy are checked before a single byte is read.
//   4. Commit: textures, materials, meshes, entities, skins, animations are
//      added to the World. Nothing in this stage can fail on bad input, so a
//      throwing load leaves the World exactly as it was.
//
// Decisions worth knowing:
//   - Scene selection: `scene` if present, else scenes[0]. When the file has
//     no scenes at all (e.g. TestNoRootNode/NoScene.gltf, whose `scene: 0`
//     references nothing) every node that is nobody's child is a root; with
//     no nodes that loads nothing and succeeds.
//   - Node hierarchies must be strict forests: a child listed twice, a node
//     with two parents, or a cycle (RecursiveNodes.gltf) is an InputError.
//     Traversal is iterative, so deep hierarchies cannot blow the stack.
//   - Only meshes, materials and textures reachable from the loaded scene's
//     nodes are converted (and therefore validated); animations are all
//     validated, channels that target nodes outside the loaded scene are
//     dropped, channels without a target node are ignored (glTF spec).
//   - Primitive modes: triangles, strips and fans (converted to lists with
//     the spec's winding). Points and lines are validated, then skipped and
//     counted (World::loadReport(), one warning line per file); a node
//     whose mesh has nothing else gets no MeshInstance.
//   - Non-finite positions, normals, UVs, weights or animation values are
//     InputErrors. Zero-length normals are replaced per vertex by generated
//     ones; missing normals are generated.
//   - Skin weights are renormalised to sum to 1 (all-zero weights become
//     (1,0,0,0)); joint indices with non-zero weight must be < joint count.
//   - Sparse accessors are supported.
//   - Orthographic cameras are approximated by a perspective camera
//     (yfov 0.8, aspect xmag/ymag); Camera has no orthographic mode.
//   - A baseColorTexture that uses texCoord != 0 is dropped (only UV0 is
//     loaded), as is a texture without decoded image data or with an
//     unsupported pixel format (not 8/16-bit, 1-4 channels).
//   - Compressed geometry: KHR_draco_mesh_compression (decoded per primitive;
//     its attributes replace the accessors they name, its faces the indices),
//     EXT_meshopt_compression (bufferViews decoded in place after tinygltf;
//     fallback buffers without data are handed to tinygltf as placeholders)
//     and KHR_mesh_quantization (integer positions, normals, UVs, morph
//     deltas, accepted when the file lists the extension). Decoders live in
//     gltf_compression.cpp.
//   - A file that *requires* an extension outside isSupportedExtension()
//     (docs/scene-format.md, "glTF support") is rejected naming it;
//     KHR_texture_transform etc. are ignored when merely used.
#define GLM_ENABLE_EXPERIMENTAL

#include "gltf_compression.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <glm/gtx/matrix_decompose.hpp>
#include <nlohmann/json.hpp>
#include <tiny_gltf.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace rtlab::ecs::load {
namespace {

namespace tg = tinygltf;
using Json = nlohmann::json;

// Limits that keep malformed input from exhausting the stack or memory.
constexpr std::size_t kMaxJsonDepth = 128;                    // glTF itself nests < 10 deep
constexpr std::uint64_t kMaxJsonInteger = 0x7fffffffu;        // tinygltf stores indices in int
constexpr std::size_t kMaxUnbackedAccessorElements = 1u << 24;  // accessors without bufferView are zeros
constexpr float kInfiniteFar = 1e30f;                           // zfar for glTF's infinite projection

constexpr int kByte = TINYGLTF_COMPONENT_TYPE_BYTE;
constexpr int kUByte = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
constexpr int kShort = TINYGLTF_COMPONENT_TYPE_SHORT;
constexpr int kUShort = TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
constexpr int kUInt = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
constexpr int kFloat = TINYGLTF_COMPONENT_TYPE_FLOAT;

template <class... Args>
std::string cat(const Args&... args) {
    std::ostringstream s;
    (s << ... << args);
    return s.str();
}

// Throws InputError naming the file.
class Fail {
public:
    explicit Fail(std::string file) : file_(std::move(file)) {}
    [[noreturn]] void operator()(const std::string& what) const { throw InputError(file_, what); }

private:
    std::string file_;
};

std::string lowercase(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return s;
}

// First non-blank line, trimmed, at most ~300 characters (tinygltf quotes
// whole data URIs in some messages).
std::string firstLineTrimmed(const std::string& text) {
    std::size_t begin = 0;
    // Skip leading blank lines.
    while (begin < text.size() && std::isspace(static_cast<unsigned char>(text[begin]))) ++begin;
    std::size_t end = text.find_first_of("\r\n", begin);
    if (end == std::string::npos) end = text.size();
    while (end > begin && std::isspace(static_cast<unsigned char>(text[end - 1]))) --end;
    constexpr std::size_t kMaxLength = 300;
    if (end - begin > kMaxLength) return text.substr(begin, kMaxLength) + "...";
    return text.substr(begin, end - begin);
}

// ===========================================================================
// Stage 1: structural pre-check of the JSON.
// ===========================================================================

enum class Kind : std::uint8_t {
    UInt,          // integer in [0, kMaxJsonInteger]
    Number,        // finite number
    Bool,
    String,
    Object,        // nested schema
    UIntArray,
    NumberArray,   // optionally of fixed length
    StringArray,
    ObjectArray,   // array of nested schema
    UIntMap,       // object whose values are UInt (primitive attributes)
    UIntMapArray,  // array of UIntMap (morph targets)
};

struct Schema;
struct Prop {
    Prop(const char* n, Kind k, bool req = false, std::size_t len = 0, const Schema* s = nullptr, bool nonEmptyArray = false)
        : name(n), kind(k), required(req), length(len), schema(s), nonEmpty(nonEmptyArray) {}
    const char* name;
    Kind kind;
    bool required;
    std::size_t length;    // NumberArray: fixed length, 0 = any
    const Schema* schema;  // Object, ObjectArray
    bool nonEmpty;         // arrays: minItems 1
};
struct ExtensionSchema {
    const char* name;
    const Schema* schema;
};
struct Schema {
    Schema(std::vector<Prop> p, std::vector<ExtensionSchema> e = {}) : props(std::move(p)), extensions(std::move(e)) {}
    std::vector<Prop> props;
    std::vector<ExtensionSchema> extensions;  // known extensions checked in depth
};

Prop uintProp(const char* n, bool required = false) { return {n, Kind::UInt, required}; }
Prop numberProp(const char* n, bool required = false) { return {n, Kind::Number, required}; }
Prop boolProp(const char* n) { return {n, Kind::Bool}; }
Prop stringProp(const char* n, bool required = false) { return {n, Kind::String, required}; }
Prop objectProp(const char* n, const Schema& s, bool required = false) { return {n, Kind::Object, required, 0, &s}; }
Prop uintArrayProp(const char* n, bool required = false, bool nonEmpty = false) {
    return {n, Kind::UIntArray, required, 0, nullptr, nonEmpty};
}
Prop numberArrayProp(const char* n, std::size_t length = 0) { return {n, Kind::NumberArray, false, length}; }
Prop stringArrayProp(const char* n) { return {n, Kind::StringArray}; }
Prop objectArrayProp(const char* n, const Schema& s, bool required = false, bool nonEmpty = false) {
    return {n, Kind::ObjectArray, required, 0, &s, nonEmpty};
}

// The subset of the glTF 2.0 JSON schema that matters for type safety.
const Schema& gltfSchema() {
    static const Schema textureInfo{{uintProp("index", true), uintProp("texCoord"), numberProp("scale"),
                                     numberProp("strength")}};
    static const Schema transmissionExt{{numberProp("transmissionFactor"), objectProp("transmissionTexture", textureInfo)}};
    static const Schema iorExt{{numberProp("ior")}};
    static const Schema volumeExt{{numberProp("thicknessFactor"), objectProp("thicknessTexture", textureInfo),
                                   numberProp("attenuationDistance"), numberArrayProp("attenuationColor", 3)}};
    static const Schema emissiveStrengthExt{{numberProp("emissiveStrength")}};
    static const Schema pbr{{numberArrayProp("baseColorFactor", 4), objectProp("baseColorTexture", textureInfo),
                             numberProp("metallicFactor"), numberProp("roughnessFactor"),
                             objectProp("metallicRoughnessTexture", textureInfo)}};
    static const Schema material{{objectProp("pbrMetallicRoughness", pbr), objectProp("normalTexture", textureInfo),
                                  objectProp("occlusionTexture", textureInfo), objectProp("emissiveTexture", textureInfo),
                                  numberArrayProp("emissiveFactor", 3), stringProp("alphaMode"),
                                  numberProp("alphaCutoff"), boolProp("doubleSided")},
                                 {{"KHR_materials_transmission", &transmissionExt},
                                  {"KHR_materials_ior", &iorExt},
                                  {"KHR_materials_volume", &volumeExt},
                                  {"KHR_materials_emissive_strength", &emissiveStrengthExt}}};
    static const Schema dracoExt{{uintProp("bufferView", true), {"attributes", Kind::UIntMap, true}}};
    static const Schema primitive{{{"attributes", Kind::UIntMap, true}, uintProp("indices"), uintProp("material"),
                                   uintProp("mode"), {"targets", Kind::UIntMapArray}},
                                  {{"KHR_draco_mesh_compression", &dracoExt}}};
    static const Schema mesh{{objectArrayProp("primitives", primitive, true, true), numberArrayProp("weights")}};
    static const Schema nodeLight{{uintProp("light", true)}};
    static const Schema node{{uintProp("camera"), uintProp("skin"), uintProp("mesh"), uintArrayProp("children"),
                              numberArrayProp("matrix", 16), numberArrayProp("rotation", 4),
                              numberArrayProp("scale", 3), numberArrayProp("translation", 3),
                              numberArrayProp("weights")},
                             {{"KHR_lights_punctual", &nodeLight}}};
    static const Schema scene{{uintArrayProp("nodes")}};
    static const Schema sparseIndices{{uintProp("bufferView", true), uintProp("byteOffset"), uintProp("componentType", true)}};
    static const Schema sparseValues{{uintProp("bufferView", true), uintProp("byteOffset")}};
    static const Schema sparse{{uintProp("count", true), objectProp("indices", sparseIndices, true),
                                objectProp("values", sparseValues, true)}};
    static const Schema accessor{{uintProp("bufferView"), uintProp("byteOffset"), uintProp("componentType", true),
                                  boolProp("normalized"), uintProp("count", true), stringProp("type", true),
                                  numberArrayProp("max"), numberArrayProp("min"), objectProp("sparse", sparse)}};
    static const Schema meshoptViewExt{{uintProp("buffer", true), uintProp("byteOffset"), uintProp("byteLength", true),
                                        uintProp("byteStride", true), uintProp("count", true), stringProp("mode", true),
                                        stringProp("filter")}};
    static const Schema bufferView{{uintProp("buffer", true), uintProp("byteOffset"), uintProp("byteLength", true),
                                    uintProp("byteStride"), uintProp("target")},
                                   {{"EXT_meshopt_compression", &meshoptViewExt}}};
    static const Schema meshoptBufferExt{{boolProp("fallback")}};
    static const Schema buffer{{stringProp("uri"), uintProp("byteLength", true)},
                               {{"EXT_meshopt_compression", &meshoptBufferExt}}};
    static const Schema image{{stringProp("uri"), stringProp("mimeType"), uintProp("bufferView")}};
    static const Schema texture{{uintProp("sampler"), uintProp("source")}};
    static const Schema sampler{{uintProp("magFilter"), uintProp("minFilter"), uintProp("wrapS"), uintProp("wrapT")}};
    static const Schema skin{{uintProp("inverseBindMatrices"), uintProp("skeleton"), uintArrayProp("joints", true, true)}};
    static const Schema perspective{{numberProp("aspectRatio"), numberProp("yfov", true), numberProp("zfar"),
                                     numberProp("znear", true)}};
    static const Schema orthographic{{numberProp("xmag", true), numberProp("ymag", true), numberProp("zfar", true),
                                      numberProp("znear", true)}};
    static const Schema camera{{stringProp("type", true), objectProp("perspective", perspective),
                                objectProp("orthographic", orthographic)}};
    static const Schema channelTarget{{uintProp("node"), stringProp("path", true)}};
    static const Schema channel{{uintProp("sampler", true), objectProp("target", channelTarget, true)}};
    static const Schema animationSampler{{uintProp("input", true), stringProp("interpolation"), uintProp("output", true)}};
    static const Schema animation{{objectArrayProp("channels", channel, true), objectArrayProp("samplers", animationSampler, true)}};
    static const Schema asset{{stringProp("version", true), stringProp("generator"), stringProp("minVersion"),
                               stringProp("copyright")}};
    static const Schema spot{{numberProp("innerConeAngle"), numberProp("outerConeAngle")}};
    static const Schema light{{stringProp("type", true), numberArrayProp("color", 3), numberProp("intensity"),
                               numberProp("range"), objectProp("spot", spot)}};
    static const Schema lightsExt{{objectArrayProp("lights", light, true)}};
    static const Schema root{{objectProp("asset", asset, true), uintProp("scene"), objectArrayProp("scenes", scene),
                              objectArrayProp("nodes", node), objectArrayProp("meshes", mesh),
                              objectArrayProp("accessors", accessor), objectArrayProp("bufferViews", bufferView),
                              objectArrayProp("buffers", buffer), objectArrayProp("images", image),
                              objectArrayProp("textures", texture), objectArrayProp("samplers", sampler),
                              objectArrayProp("materials", material), objectArrayProp("skins", skin),
                              objectArrayProp("cameras", camera), objectArrayProp("animations", animation),
                              stringArrayProp("extensionsUsed"), stringArrayProp("extensionsRequired")},
                             {{"KHR_lights_punctual", &lightsExt}}};
    return root;
}

bool isJsonUInt(const Json& v) {
    if (v.is_number_unsigned()) return v.get<std::uint64_t>() <= kMaxJsonInteger;
    if (v.is_number_integer()) {
        const std::int64_t i = v.get<std::int64_t>();
        return i >= 0 && static_cast<std::uint64_t>(i) <= kMaxJsonInteger;
    }
    if (v.is_number_float()) {
        const double d = v.get<double>();
        return std::isfinite(d) && d >= 0.0 && d <= static_cast<double>(kMaxJsonInteger) && d == std::floor(d);
    }
    return false;
}
bool isJsonNumber(const Json& v) { return v.is_number() && std::isfinite(v.get<double>()); }

class JsonChecker {
public:
    explicit JsonChecker(const Fail& fail) : fail_(fail) {}

    void checkObject(const Json& j, const Schema& schema, const std::string& path) const {
        if (!j.is_object()) fail_(cat(path, ": expected a JSON object"));
        if (const auto it = j.find("name"); it != j.end() && !it->is_string())
            fail_(cat(path, ".name: expected a string"));
        if (const auto it = j.find("extensions"); it != j.end()) {
            const std::string extPath = cat(path, ".extensions");
            if (!it->is_object()) fail_(cat(extPath, ": expected a JSON object"));
            for (const auto& [key, value] : it->items()) {
                if (!value.is_object()) fail_(cat(extPath, ".", key, ": expected a JSON object"));
                for (const ExtensionSchema& ext : schema.extensions)
                    if (key == ext.name) checkObject(value, *ext.schema, cat(extPath, ".", key));
            }
        }
        for (const Prop& p : schema.props) {
            const auto it = j.find(p.name);
            if (it == j.end()) {
                if (p.required) fail_(cat(path, ": missing required property '", p.name, "'"));
                continue;
            }
            checkProp(*it, p, path.empty() ? std::string(p.name) : cat(path, ".", p.name));
        }
    }

private:
    void checkProp(const Json& v, const Prop& p, const std::string& path) const {
        switch (p.kind) {
            case Kind::UInt:
                if (!isJsonUInt(v)) fail_(cat(path, ": expected a non-negative integer"));
                break;
            case Kind::Number:
                if (!isJsonNumber(v)) fail_(cat(path, ": expected a number"));
                break;
            case Kind::Bool:
                if (!v.is_boolean()) fail_(cat(path, ": expected true or false"));
                break;
            case Kind::String:
                if (!v.is_string()) fail_(cat(path, ": expected a string"));
                break;
            case Kind::Object: checkObject(v, *p.schema, path); break;
            case Kind::UIntArray:
                checkArray(v, p, path);
                for (std::size_t i = 0; i < v.size(); ++i)
                    if (!isJsonUInt(v[i])) fail_(cat(path, "[", i, "]: expected a non-negative integer"));
                break;
            case Kind::NumberArray:
                checkArray(v, p, path);
                if (p.length != 0 && v.size() != p.length)
                    fail_(cat(path, ": expected an array of ", p.length, " numbers"));
                for (std::size_t i = 0; i < v.size(); ++i)
                    if (!isJsonNumber(v[i])) fail_(cat(path, "[", i, "]: expected a number"));
                break;
            case Kind::StringArray:
                checkArray(v, p, path);
                for (std::size_t i = 0; i < v.size(); ++i)
                    if (!v[i].is_string()) fail_(cat(path, "[", i, "]: expected a string"));
                break;
            case Kind::ObjectArray:
                checkArray(v, p, path);
                for (std::size_t i = 0; i < v.size(); ++i) checkObject(v[i], *p.schema, cat(path, "[", i, "]"));
                break;
            case Kind::UIntMap: checkUIntMap(v, path); break;
            case Kind::UIntMapArray:
                checkArray(v, p, path);
                for (std::size_t i = 0; i < v.size(); ++i) checkUIntMap(v[i], cat(path, "[", i, "]"));
                break;
        }
    }
    void checkArray(const Json& v, const Prop& p, const std::string& path) const {
        if (!v.is_array()) fail_(cat(path, ": expected an array"));
        if (p.nonEmpty && v.empty()) fail_(cat(path, ": must not be empty"));
    }
    void checkUIntMap(const Json& v, const std::string& path) const {
        if (!v.is_object()) fail_(cat(path, ": expected a JSON object"));
        for (const auto& [key, value] : v.items())
            if (!isJsonUInt(value)) fail_(cat(path, ".", key, ": expected a non-negative integer"));
    }

    const Fail& fail_;
};

std::uint32_t readLe32(const unsigned char* p) {
    return std::uint32_t(p[0]) | (std::uint32_t(p[1]) << 8) | (std::uint32_t(p[2]) << 16) | (std::uint32_t(p[3]) << 24);
}

// Reads the JSON text of a .gltf file, or the JSON chunk of a .glb after
// checking the container layout (header, chunk lengths).
std::string readJsonText(const std::filesystem::path& path, bool binary, const Fail& fail) {
    std::ifstream in(path, std::ios::binary);
    if (!in) fail("cannot open file");
    in.seekg(0, std::ios::end);
    const std::streamoff fileSizeOff = in.tellg();
    in.seekg(0, std::ios::beg);
    if (fileSizeOff < 0) fail("cannot read file");
    const auto fileSize = static_cast<std::uint64_t>(fileSizeOff);
    if (!binary) {
        std::string text(static_cast<std::size_t>(fileSize), '\0');
        if (fileSize > 0 && !in.read(text.data(), static_cast<std::streamsize>(fileSize))) fail("cannot read file");
        return text;
    }
    unsigned char header[20];
    if (fileSize < sizeof(header) || !in.read(reinterpret_cast<char*>(header), sizeof(header)))
        fail("not a binary glTF file (shorter than the 20-byte GLB header)");
    if (std::memcmp(header, "glTF", 4) != 0) fail("not a binary glTF file (bad GLB magic)");
    if (readLe32(header + 4) != 2) fail(cat("unsupported GLB container version ", readLe32(header + 4)));
    const std::uint64_t declared = readLe32(header + 8);
    if (declared != fileSize)
        fail(cat("GLB header declares ", declared, " bytes but the file has ", fileSize));
    const std::uint64_t jsonLength = readLe32(header + 12);
    if (readLe32(header + 16) != 0x4E4F534Au) fail("GLB: the first chunk is not a JSON chunk");
    if (jsonLength == 0 || jsonLength > fileSize - 20) fail("GLB: JSON chunk length exceeds the file");
    const std::uint64_t binStart = 20 + jsonLength;
    if (binStart < fileSize) {
        // A following chunk needs a full 8-byte header and must fit the file.
        unsigned char chunk[8];
        in.seekg(static_cast<std::streamoff>(binStart), std::ios::beg);
        if (fileSize - binStart < 8 || !in.read(reinterpret_cast<char*>(chunk), 8))
            fail("GLB: truncated chunk header after the JSON chunk");
        if (readLe32(chunk) > fileSize - binStart - 8) fail("GLB: BIN chunk length exceeds the file");
        in.seekg(20, std::ios::beg);
    }
    std::string text(static_cast<std::size_t>(jsonLength), '\0');
    if (!in.read(text.data(), static_cast<std::streamsize>(jsonLength))) fail("cannot read GLB JSON chunk");
    return text;
}

std::uint64_t jsonUInt(const Json& obj, const char* key, std::uint64_t fallback) {
    const auto it = obj.find(key);
    return it == obj.end() ? fallback : static_cast<std::uint64_t>(it->get<double>());
}

bool isSupportedExtension(const std::string& name) {
    static const std::array<std::string_view, 8> kSupported = {
        "KHR_lights_punctual",         "KHR_materials_transmission", "KHR_materials_ior",
        "KHR_materials_volume",        "KHR_materials_emissive_strength", "KHR_draco_mesh_compression",
        "EXT_meshopt_compression",     "KHR_mesh_quantization"};
    return std::find(kSupported.begin(), kSupported.end(), name) != kSupported.end();
}

// Deepest nesting of objects/arrays, by a linear scan that skips strings.
// (nlohmann's callback parser would do this too, but quadratically on big arrays.)
std::size_t jsonNestingDepth(std::string_view text) {
    std::size_t depth = 0, deepest = 0;
    bool inString = false, escaped = false;
    for (const char c : text) {
        if (inString) {
            if (escaped) escaped = false;
            else if (c == '\\') escaped = true;
            else if (c == '"') inString = false;
        } else if (c == '"') {
            inString = true;
        } else if (c == '{' || c == '[') {
            deepest = std::max(deepest, ++depth);
        } else if ((c == '}' || c == ']') && depth > 0) {
            --depth;
        }
    }
    return deepest;
}

// One EXT_meshopt_compression bufferView: compressed bytes in a source
// buffer, decoded into the bufferView's own range (often of a fallback
// buffer that has no data in the file).
struct MeshoptView {
    std::size_t view = 0;
    std::size_t sourceBuffer = 0;
    std::uint64_t sourceOffset = 0, sourceLength = 0;
    std::uint64_t count = 0, stride = 0;
    compression::MeshoptMode mode = compression::MeshoptMode::Attributes;
    compression::MeshoptFilter filter = compression::MeshoptFilter::None;
};

// What the pre-check learned that the later stages need.
struct Prechecked {
    std::vector<MeshoptView> meshopt;
    // Fallback buffers without data (EXT_meshopt_compression): index and the
    // bytes their bufferViews cover. tinygltf cannot load a buffer without a
    // uri, so they are handed to it as 1-byte placeholders and zero-filled
    // afterwards.
    std::vector<std::pair<std::size_t, std::uint64_t>> placeholders;
    // Draco primitives whose indices accessor has no bufferView (the indices
    // are in the Draco data): tinygltf rejects those, so the JSON it parses
    // lacks their `indices`, restored afterwards. (mesh, primitive, accessor)
    std::vector<std::array<std::size_t, 3>> hiddenIndices;
    std::string rewrittenJson;  // non-empty: tinygltf parses this JSON instead of the file's
};

void precheckDraco(Json& doc, Prechecked& out) {
    if (!doc.contains("meshes")) return;
    const Json empty = Json::array();
    const Json& accessors = doc.contains("accessors") ? doc["accessors"] : empty;
    Json& meshes = doc["meshes"];
    for (std::size_t m = 0; m < meshes.size(); ++m) {
        Json& primitives = meshes[m]["primitives"];
        for (std::size_t p = 0; p < primitives.size(); ++p) {
            Json& prim = primitives[p];
            const auto ext = prim.find("extensions");
            if (ext == prim.end() || !ext->contains("KHR_draco_mesh_compression") || !prim.contains("indices")) continue;
            const std::size_t indices = jsonUInt(prim, "indices", 0);
            if (indices < accessors.size() && accessors[indices].contains("bufferView")) continue;
            out.hiddenIndices.push_back({m, p, indices});
            prim.erase("indices");
        }
    }
}

// meshopt's codecs store at least 2 bits per 16 decoded bytes (vertex
// codec; the index codecs need more), so a bufferView cannot decode to more
// than this: larger claims are malformed and are refused before any memory
// is set aside for them.
std::uint64_t maxMeshoptDecodedBytes(std::uint64_t compressedBytes) { return 64 * compressedBytes + 65536; }

void precheckMeshopt(Json& doc, Prechecked& out, const Fail& fail) {
    const Json empty = Json::array();
    const Json& buffers = doc.contains("buffers") ? doc["buffers"] : empty;
    const Json& views = doc.contains("bufferViews") ? doc["bufferViews"] : empty;
    std::vector<std::uint8_t> placeholder(buffers.size(), 0);
    for (std::size_t i = 0; i < buffers.size(); ++i) {
        const Json& b = buffers[i];
        const auto ext = b.find("extensions");
        if (b.contains("uri") || ext == b.end() || !ext->contains("EXT_meshopt_compression")) continue;
        placeholder[i] = (*ext)["EXT_meshopt_compression"].value("fallback", false);
    }
    // Per placeholder buffer: the bytes its views cover, and what they may decode to.
    std::vector<std::uint64_t> covered(buffers.size(), 0), decodable(buffers.size(), 0);
    for (std::size_t i = 0; i < views.size(); ++i) {
        const auto ext = views[i].find("extensions");
        const bool compressed = ext != views[i].end() && ext->contains("EXT_meshopt_compression");
        const std::size_t target = jsonUInt(views[i], "buffer", 0);  // < buffers.size(): checked before
        if (!compressed) {
            if (placeholder[target])
                fail(cat("bufferViews[", i, "] is not EXT_meshopt_compression-compressed but uses fallback buffer ",
                         target, ", which has no data"));
            continue;
        }
        const Json& m = (*ext)["EXT_meshopt_compression"];
        const std::string where = cat("bufferViews[", i, "].extensions.EXT_meshopt_compression");
        MeshoptView v;
        v.view = i;
        v.sourceBuffer = jsonUInt(m, "buffer", 0);
        v.sourceOffset = jsonUInt(m, "byteOffset", 0);
        v.sourceLength = jsonUInt(m, "byteLength", 0);
        v.count = jsonUInt(m, "count", 0);
        v.stride = jsonUInt(m, "byteStride", 0);
        if (v.sourceBuffer >= buffers.size()) fail(cat(where, ".buffer ", v.sourceBuffer, " is out of range"));
        if (placeholder[v.sourceBuffer]) fail(cat(where, ".buffer ", v.sourceBuffer, " is a fallback buffer without data"));
        const std::uint64_t sourceBytes = jsonUInt(buffers[v.sourceBuffer], "byteLength", 0);
        if (v.sourceOffset > sourceBytes || v.sourceLength > sourceBytes - v.sourceOffset)
            fail(cat(where, " (byteOffset ", v.sourceOffset, " + byteLength ", v.sourceLength, ") exceeds buffers[",
                     v.sourceBuffer, "] (", sourceBytes, " bytes)"));
        if (v.stride == 0 || v.count == 0) fail(cat(where, ": byteStride and count must be at least 1"));
        const std::uint64_t viewOffset = jsonUInt(views[i], "byteOffset", 0), viewBytes = jsonUInt(views[i], "byteLength", 0);
        if (v.count > viewBytes / v.stride)
            fail(cat(where, ": ", v.count, " elements of ", v.stride, " bytes exceed the bufferView's ", viewBytes,
                     " bytes"));
        if (viewBytes > maxMeshoptDecodedBytes(v.sourceLength))
            fail(cat(where, ": ", v.sourceLength, " compressed bytes cannot fill the bufferView's ", viewBytes,
                     " bytes"));
        covered[target] = std::max(covered[target], viewOffset + viewBytes);
        decodable[target] += maxMeshoptDecodedBytes(v.sourceLength);
        const std::string mode = m["mode"].get<std::string>(), filter = m.value("filter", std::string("NONE"));
        if (mode == "ATTRIBUTES") v.mode = compression::MeshoptMode::Attributes;
        else if (mode == "TRIANGLES") v.mode = compression::MeshoptMode::Triangles;
        else if (mode == "INDICES") v.mode = compression::MeshoptMode::Indices;
        else fail(cat(where, ": unknown mode '", mode, "'"));
        if (filter == "NONE") v.filter = compression::MeshoptFilter::None;
        else if (filter == "OCTAHEDRAL") v.filter = compression::MeshoptFilter::Octahedral;
        else if (filter == "QUATERNION") v.filter = compression::MeshoptFilter::Quaternion;
        else if (filter == "EXPONENTIAL") v.filter = compression::MeshoptFilter::Exponential;
        else fail(cat(where, ": unknown filter '", filter, "'"));
        out.meshopt.push_back(v);
    }
    for (std::size_t i = 0; i < buffers.size(); ++i) {
        if (!placeholder[i]) continue;
        if (covered[i] > decodable[i])
            fail(cat("buffers[", i, "]: its EXT_meshopt_compression bufferViews cover ", covered[i],
                     " bytes, more than their compressed data can decode to"));
        out.placeholders.emplace_back(i, covered[i]);
        doc["buffers"][i]["uri"] = "data:application/octet-stream;base64,AA==";
        doc["buffers"][i]["byteLength"] = 1;
    }
}

// The file's bytes with its JSON (chunk) replaced by `json`.
std::string withJson(const std::filesystem::path& path, bool binary, const std::string& json, const Fail& fail) {
    if (!binary) return json;
    std::ifstream in(path, std::ios::binary);
    const std::string file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in && !in.eof()) fail("cannot read file");
    // Layout checked by readJsonText: 20-byte header + JSON chunk, then the rest.
    const std::size_t rest = 20 + readLe32(reinterpret_cast<const unsigned char*>(file.data()) + 12);
    std::string chunk = json;
    while (chunk.size() % 4 != 0) chunk += ' ';
    const std::size_t total = 20 + chunk.size() + (file.size() - rest);
    if (total > 0xffffffffu) fail("GLB too large");
    std::string out;
    auto le32 = [&](std::uint32_t v) {
        for (int b = 0; b < 4; ++b) out += static_cast<char>((v >> (8 * b)) & 0xffu);
    };
    out += "glTF";
    le32(2);
    le32(static_cast<std::uint32_t>(total));
    le32(static_cast<std::uint32_t>(chunk.size()));
    le32(0x4E4F534Au);
    out += chunk;
    out.append(file, rest, std::string::npos);
    return out;
}

Prechecked precheckJson(const std::filesystem::path& path, bool binary, const Fail& fail) {
    const std::string text = readJsonText(path, binary, fail);
    // Before parsing: tinygltf converts extras/extensions recursively.
    if (jsonNestingDepth(text) > kMaxJsonDepth) fail(cat("JSON nested deeper than ", kMaxJsonDepth, " levels"));
    Json doc;
    try {
        doc = Json::parse(text);
    } catch (const Json::exception& e) {
        // "[json.exception.parse_error.101] parse error at line 1, ...": keep the readable part.
        std::string what = e.what();
        if (const std::size_t close = what.find("] "); close != std::string::npos) what = what.substr(close + 2);
        fail(cat("invalid JSON: ", firstLineTrimmed(what)));
    }
    if (!doc.is_object()) fail("invalid glTF: the top-level JSON value is not an object");

    JsonChecker(fail).checkObject(doc, gltfSchema(), "");

    const std::string version = doc["asset"]["version"].get<std::string>();
    if (version.rfind("2.", 0) != 0) fail(cat("unsupported glTF version '", version, "' (expected 2.x)"));
    if (const auto it = doc.find("extensionsRequired"); it != doc.end())
        for (const Json& ext : *it)
            if (!isSupportedExtension(ext.get<std::string>()))
                fail(cat("requires unsupported glTF extension ", ext.get<std::string>()));

    // Extents tinygltf relies on without checking: bufferViews inside their
    // buffers (tinygltf guarantees buffer data size == byteLength), images'
    // bufferViews in range.
    const Json empty = Json::array();
    const Json& buffers = doc.contains("buffers") ? doc["buffers"] : empty;
    const Json& views = doc.contains("bufferViews") ? doc["bufferViews"] : empty;
    for (std::size_t i = 0; i < buffers.size(); ++i)
        if (jsonUInt(buffers[i], "byteLength", 0) == 0) fail(cat("buffers[", i, "].byteLength must be at least 1"));
    for (std::size_t i = 0; i < views.size(); ++i) {
        const Json& v = views[i];
        const std::uint64_t b = jsonUInt(v, "buffer", 0);
        if (b >= buffers.size()) fail(cat("bufferViews[", i, "].buffer ", b, " is out of range"));
        const std::uint64_t offset = jsonUInt(v, "byteOffset", 0), length = jsonUInt(v, "byteLength", 0);
        const std::uint64_t bufferLength = jsonUInt(buffers[b], "byteLength", 0);
        if (length == 0) fail(cat("bufferViews[", i, "].byteLength must be at least 1"));
        if (offset + length > bufferLength)
            fail(cat("bufferViews[", i, "] (byteOffset ", offset, " + byteLength ", length, ") exceeds buffers[", b,
                     "] (", bufferLength, " bytes)"));
        const std::uint64_t stride = jsonUInt(v, "byteStride", 0);
        if (v.contains("byteStride") && (stride < 4 || stride > 252))
            fail(cat("bufferViews[", i, "].byteStride ", stride, " is outside [4, 252]"));
    }
    if (const auto it = doc.find("images"); it != doc.end())
        for (std::size_t i = 0; i < it->size(); ++i)
            if (const auto bv = (*it)[i].find("bufferView"); bv != (*it)[i].end() && bv->get<double>() >= views.size())
                fail(cat("images[", i, "].bufferView is out of range"));

    Prechecked out;
    precheckMeshopt(doc, out, fail);
    precheckDraco(doc, out);
    if (!out.placeholders.empty() || !out.hiddenIndices.empty())
        out.rewrittenJson = withJson(path, binary, doc.dump(), fail);
    return out;
}

void restoreHiddenIndices(tg::Model& model, const Prechecked& pre) {
    for (const auto& [mesh, primitive, accessor] : pre.hiddenIndices)
        model.meshes.at(mesh).primitives.at(primitive).indices = static_cast<int>(accessor);
}

// Gives placeholder buffers the size their views cover and decodes every
// EXT_meshopt_compression bufferView into place (after tinygltf, before stage 3).
void decodeMeshoptViews(tg::Model& model, const Prechecked& pre, const Fail& fail) {
    for (const auto& [index, bytes] : pre.placeholders)
        model.buffers.at(index).data.assign(static_cast<std::size_t>(bytes), 0);
    for (const MeshoptView& v : pre.meshopt) {
        const tg::BufferView& view = model.bufferViews.at(v.view);
        std::vector<unsigned char>& target = model.buffers.at(static_cast<std::size_t>(view.buffer)).data;
        const std::vector<unsigned char>& source = model.buffers.at(v.sourceBuffer).data;
        if (v.sourceOffset + v.sourceLength > source.size() || view.byteOffset + v.count * v.stride > target.size())
            fail(cat("bufferViews[", v.view, "]: EXT_meshopt_compression data exceeds its buffer"));
        const std::string problem =
            compression::decodeMeshopt(target.data() + view.byteOffset, source.data() + v.sourceOffset,
                                       static_cast<std::size_t>(v.sourceLength), static_cast<std::size_t>(v.count),
                                       static_cast<std::size_t>(v.stride), v.mode, v.filter);
        if (!problem.empty()) fail(cat("bufferViews[", v.view, "]: EXT_meshopt_compression: ", problem));
    }
}

// ===========================================================================
// Stage 3: semantic validation and conversion into staging structures.
// ===========================================================================

int componentSize(int componentType) {
    switch (componentType) {
        case kByte:
        case kUByte: return 1;
        case kShort:
        case kUShort: return 2;
        case kUInt:
        case kFloat: return 4;
        default: return 0;
    }
}
int componentCount(int type) {
    switch (type) {
        case TINYGLTF_TYPE_SCALAR: return 1;
        case TINYGLTF_TYPE_VEC2: return 2;
        case TINYGLTF_TYPE_VEC3: return 3;
        case TINYGLTF_TYPE_VEC4: return 4;
        case TINYGLTF_TYPE_MAT2: return 4;
        case TINYGLTF_TYPE_MAT3: return 9;
        case TINYGLTF_TYPE_MAT4: return 16;
        default: return 0;
    }
}
std::string typeName(int type) {
    switch (type) {
        case TINYGLTF_TYPE_SCALAR: return "SCALAR";
        case TINYGLTF_TYPE_VEC2: return "VEC2";
        case TINYGLTF_TYPE_VEC3: return "VEC3";
        case TINYGLTF_TYPE_VEC4: return "VEC4";
        case TINYGLTF_TYPE_MAT2: return "MAT2";
        case TINYGLTF_TYPE_MAT3: return "MAT3";
        case TINYGLTF_TYPE_MAT4: return "MAT4";
        default: return cat("type ", type);
    }
}
std::string componentTypeName(int ct, bool normalized) {
    std::string n;
    switch (ct) {
        case kByte: n = "byte"; break;
        case kUByte: n = "unsigned byte"; break;
        case kShort: n = "short"; break;
        case kUShort: n = "unsigned short"; break;
        case kUInt: n = "unsigned int"; break;
        case kFloat: return "float";
        default: return cat("component type ", ct);
    }
    return normalized ? "normalized " + n : n;
}

// One accepted (component type, normalized) combination; for float the
// normalized flag is ignored, for integers it must match when `anyNorm` is false.
struct Format {
    int componentType;
    bool normalized = false;
    bool anyNorm = false;
};

float readFloat(const unsigned char* p, int ct, bool normalized) {
    switch (ct) {
        case kFloat: {
            float f;
            std::memcpy(&f, p, 4);
            return f;
        }
        case kByte: {
            std::int8_t v;
            std::memcpy(&v, p, 1);
            return normalized ? std::max(static_cast<float>(v) / 127.f, -1.f) : static_cast<float>(v);
        }
        case kUByte: return normalized ? static_cast<float>(p[0]) / 255.f : static_cast<float>(p[0]);
        case kShort: {
            std::int16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? std::max(static_cast<float>(v) / 32767.f, -1.f) : static_cast<float>(v);
        }
        case kUShort: {
            std::uint16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? static_cast<float>(v) / 65535.f : static_cast<float>(v);
        }
        case kUInt: {
            std::uint32_t v;
            std::memcpy(&v, p, 4);
            return normalized ? static_cast<float>(static_cast<double>(v) / 4294967295.0) : static_cast<float>(v);
        }
        default: return 0.f;
    }
}
std::uint32_t readUInt(const unsigned char* p, int ct) {
    switch (ct) {
        case kUByte: return p[0];
        case kUShort: {
            std::uint16_t v;
            std::memcpy(&v, p, 2);
            return v;
        }
        case kUInt: {
            std::uint32_t v;
            std::memcpy(&v, p, 4);
            return v;
        }
        default: return 0;
    }
}

// A validated accessor: every element lies inside its buffer.
struct AccessorView {
    int index = -1;
    const tg::Accessor* acc = nullptr;
    int components = 0;
    int componentBytes = 0;
    std::size_t count = 0;
    const unsigned char* data = nullptr;  // nullptr: no bufferView, elements are zero
    std::size_t stride = 0;
    // Sparse substitution, validated.
    std::vector<std::uint32_t> sparseIndices;
    const unsigned char* sparseValues = nullptr;
};

struct StagedNode {
    int gltfNode = -1;
    int parent = -1;  // index into Staged::nodes, -1 for roots
    std::string name;
    LocalTransform local;
    int mesh = -1;  // index into Staged::meshes
    std::optional<MorphWeights> morph;
    int skin = -1;  // glTF skin index
    std::optional<Camera> camera;
    std::optional<Light> light;
};

struct StagedSkin {
    std::vector<int> jointNodes;  // glTF node indices
    std::vector<mat4> inverseBind;
};

struct StagedChannel {
    int gltfNode = -1;
    AnimationChannel channel;
};

struct StagedClip {
    std::string name;
    std::vector<StagedChannel> channels;
};

struct Staged {
    std::vector<Texture> textures;
    std::vector<Material> materials;  // baseColorTexture: index into textures
    std::vector<MeshAsset> meshes;    // Geometry::material: index into materials
    std::vector<StagedNode> nodes;    // parents before children
    std::vector<int> roots;           // indices into nodes
    std::vector<std::optional<StagedSkin>> skins;  // by glTF skin index
    std::vector<StagedClip> clips;
    std::vector<int> nodeSlot;  // glTF node -> index into nodes, -1 if not loaded
    std::uint32_t skippedPointPrimitives = 0;  // in the converted meshes
    std::uint32_t skippedLinePrimitives = 0;   // lines, line loops and line strips
};

// Converted glTF mesh before per-instance variants are made.
struct BaseMesh {
    MeshAsset asset;  // all data: morph targets, joints/weights when present
    std::size_t targetCount = 0;
    bool skinnable = false;        // every primitive has JOINTS_0 and WEIGHTS_0
    std::uint32_t jointsNeeded = 0;  // 1 + largest joint index with non-zero weight
    int rigidVariant = -1;         // index into Staged::meshes, shared by rigid instances
};

class GltfConverter {
public:
    GltfConverter(const tg::Model& model, const Fail& fail) : m_(model), fail_(fail) {}

    Staged convert() {
        s_.nodeSlot.assign(m_.nodes.size(), -1);
        s_.skins.resize(m_.skins.size());
        materialSlot_.assign(m_.materials.size(), -1);
        imageSlot_.assign(m_.images.size(), -2);  // -2: not converted yet
        baseMeshes_.resize(m_.meshes.size());
        quantized_ = std::find(m_.extensionsUsed.begin(), m_.extensionsUsed.end(), "KHR_mesh_quantization") !=
                     m_.extensionsUsed.end();

        validateHierarchy();
        const std::vector<int> roots = sceneRoots();
        traverse(roots);
        convertAnimations();
        return std::move(s_);
    }

private:
    // ---- labels ---------------------------------------------------------------
    std::string nodeLabel(int i) const {
        const std::string& n = m_.nodes[static_cast<std::size_t>(i)].name;
        return n.empty() ? cat("node ", i) : cat("node ", i, " '", n, "'");
    }
    std::string meshLabel(int i) const {
        const std::string& n = m_.meshes[static_cast<std::size_t>(i)].name;
        return n.empty() ? cat("mesh ", i) : cat("mesh '", n, "'");
    }
    std::string materialLabel(int i) const {
        const std::string& n = m_.materials[static_cast<std::size_t>(i)].name;
        return n.empty() ? cat("material ", i) : cat("material ", i, " '", n, "'");
    }

    template <class T>
    void checkIndex(int index, const std::vector<T>& array, const char* arrayName, const std::string& user) const {
        if (index < 0 || static_cast<std::size_t>(index) >= array.size())
            fail_(cat(user, " references ", arrayName, " ", index, " but the file has ", array.size()));
    }

    // ---- hierarchy ------------------------------------------------------------
    void validateHierarchy() {
        const int n = static_cast<int>(m_.nodes.size());
        parentOf_.assign(m_.nodes.size(), -1);
        for (int i = 0; i < n; ++i) {
            for (int c : m_.nodes[static_cast<std::size_t>(i)].children) {
                checkIndex(c, m_.nodes, "child node", nodeLabel(i));
                if (c == i) fail_(cat(nodeLabel(i), " lists itself as a child (node cycle)"));
                int& p = parentOf_[static_cast<std::size_t>(c)];
                if (p != -1)
                    fail_(cat(nodeLabel(c), " is a child of both node ", p, " and node ", i,
                              " (the node hierarchy must be a tree)"));
                p = i;
            }
        }
        // Every node has at most one parent now; a node that cannot be reached
        // from a parentless node sits on a cycle.
        std::vector<std::uint8_t> reached(m_.nodes.size(), 0);
        std::vector<int> stack;
        for (int i = 0; i < n; ++i)
            if (parentOf_[static_cast<std::size_t>(i)] == -1) stack.push_back(i);
        while (!stack.empty()) {
            const int i = stack.back();
            stack.pop_back();
            reached[static_cast<std::size_t>(i)] = 1;
            for (int c : m_.nodes[static_cast<std::size_t>(i)].children) stack.push_back(c);
        }
        for (int i = 0; i < n; ++i)
            if (!reached[static_cast<std::size_t>(i)])
                fail_(cat("node hierarchy contains a cycle through ", nodeLabel(i)));
    }

    std::vector<int> sceneRoots() const {
        int sceneIndex = m_.defaultScene;
        if (sceneIndex < 0 && !m_.scenes.empty()) sceneIndex = 0;
        if (sceneIndex >= 0 && m_.scenes.empty()) sceneIndex = -1;  // `scene` without `scenes`: see file comment
        std::vector<int> roots;
        if (sceneIndex < 0) {
            for (std::size_t i = 0; i < m_.nodes.size(); ++i)
                if (parentOf_[i] == -1) roots.push_back(static_cast<int>(i));
            return roots;
        }
        checkIndex(sceneIndex, m_.scenes, "scene", "the default scene");
        std::vector<std::uint8_t> seen(m_.nodes.size(), 0);
        for (int r : m_.scenes[static_cast<std::size_t>(sceneIndex)].nodes) {
            checkIndex(r, m_.nodes, "node", cat("scene ", sceneIndex));
            if (parentOf_[static_cast<std::size_t>(r)] != -1)
                fail_(cat("scene ", sceneIndex, " lists ", nodeLabel(r), " as a root, but it is a child of node ",
                          parentOf_[static_cast<std::size_t>(r)]));
            if (seen[static_cast<std::size_t>(r)]) fail_(cat("scene ", sceneIndex, " lists ", nodeLabel(r), " twice"));
            seen[static_cast<std::size_t>(r)] = 1;
            roots.push_back(r);
        }
        return roots;
    }

    // Iterative pre-order traversal: parents are staged before children.
    void traverse(const std::vector<int>& roots) {
        std::vector<std::pair<int, int>> stack;  // (glTF node, staged parent)
        for (auto it = roots.rbegin(); it != roots.rend(); ++it) stack.emplace_back(*it, -1);
        while (!stack.empty()) {
            const auto [gltfNode, parent] = stack.back();
            stack.pop_back();
            const int slot = static_cast<int>(s_.nodes.size());
            s_.nodes.push_back(stageNode(gltfNode, parent));
            s_.nodeSlot[static_cast<std::size_t>(gltfNode)] = slot;
            if (parent < 0) s_.roots.push_back(slot);
            const auto& children = m_.nodes[static_cast<std::size_t>(gltfNode)].children;
            for (auto it = children.rbegin(); it != children.rend(); ++it) stack.emplace_back(*it, slot);
        }
    }

    StagedNode stageNode(int index, int parent) {
        const tg::Node& node = m_.nodes[static_cast<std::size_t>(index)];
        StagedNode out;
        out.gltfNode = index;
        out.parent = parent;
        out.name = node.name.empty() ? cat("node ", index) : node.name;
        out.local = nodeTransform(index);

        if (node.skin >= 0) {
            checkIndex(node.skin, m_.skins, "skin", nodeLabel(index));
            if (node.mesh < 0) fail_(cat(nodeLabel(index), " has a skin but no mesh"));
        }
        if (node.mesh >= 0) {
            checkIndex(node.mesh, m_.meshes, "mesh", nodeLabel(index));
            stageInstance(index, out);
        } else if (!node.weights.empty()) {
            fail_(cat(nodeLabel(index), " has morph weights but no mesh"));
        }
        if (node.camera >= 0) {
            checkIndex(node.camera, m_.cameras, "camera", nodeLabel(index));
            out.camera = convertCamera(node.camera);
        }
        if (const auto it = node.extensions.find("KHR_lights_punctual"); it != node.extensions.end()) {
            const tg::Value& ext = it->second;
            if (!ext.IsObject() || !ext.Get("light").IsNumber())
                fail_(cat(nodeLabel(index), ": KHR_lights_punctual needs a light index"));
            const double l = ext.Get("light").GetNumberAsDouble();
            if (!(l >= 0.0 && l < static_cast<double>(m_.lights.size())) || l != std::floor(l))
                fail_(cat(nodeLabel(index), " references light ", l, " but the file has ", m_.lights.size()));
            out.light = convertLight(static_cast<int>(l));
        }
        return out;
    }

    LocalTransform nodeTransform(int index) const {
        const tg::Node& node = m_.nodes[static_cast<std::size_t>(index)];
        auto finite = [&](const std::vector<double>& v, const char* what) {
            for (double d : v)
                if (!std::isfinite(d) || std::abs(d) > 3.0e38) fail_(cat(nodeLabel(index), ": non-finite ", what));
        };
        LocalTransform t;
        if (!node.matrix.empty()) {
            if (node.matrix.size() != 16) fail_(cat(nodeLabel(index), ": matrix must have 16 elements"));
            finite(node.matrix, "matrix");
            mat4 m(1.f);
            for (int c = 0; c < 4; ++c)
                for (int r = 0; r < 4; ++r) m[c][r] = static_cast<float>(node.matrix[static_cast<std::size_t>(c * 4 + r)]);
            if (m[0][3] != 0.f || m[1][3] != 0.f || m[2][3] != 0.f || m[3][3] != 1.f)
                fail_(cat(nodeLabel(index), ": matrix has a projective part (last row must be 0 0 0 1)"));
            vec3 scale, translation, skew;
            quat rotation;
            vec4 perspective;
            const bool ok = glm::decompose(m, scale, rotation, translation, skew, perspective);
            if (ok && isFinite(scale) && isFinite(translation) && std::isfinite(rotation.w) && std::isfinite(rotation.x) &&
                std::isfinite(rotation.y) && std::isfinite(rotation.z) && glm::length(rotation) > 0.f) {
                t.translation = translation;
                t.rotation = glm::normalize(rotation);
                t.scale = scale;
            } else {
                // Singular (e.g. zero-scale) matrix: keep translation and axis
                // lengths; the rotation cannot be recovered.
                t.translation = vec3(m[3]);
                t.scale = vec3(glm::length(vec3(m[0])), glm::length(vec3(m[1])), glm::length(vec3(m[2])));
            }
            return t;
        }
        if (!node.translation.empty()) {
            if (node.translation.size() != 3) fail_(cat(nodeLabel(index), ": translation must have 3 elements"));
            finite(node.translation, "translation");
            t.translation = vec3(node.translation[0], node.translation[1], node.translation[2]);
        }
        if (!node.rotation.empty()) {
            if (node.rotation.size() != 4) fail_(cat(nodeLabel(index), ": rotation must have 4 elements"));
            finite(node.rotation, "rotation");
            const quat q(static_cast<float>(node.rotation[3]), static_cast<float>(node.rotation[0]),
                         static_cast<float>(node.rotation[1]), static_cast<float>(node.rotation[2]));
            const float len = glm::length(q);
            if (!(len > 0.f) || !std::isfinite(len)) fail_(cat(nodeLabel(index), ": rotation quaternion has zero length"));
            t.rotation = q / len;
        }
        if (!node.scale.empty()) {
            if (node.scale.size() != 3) fail_(cat(nodeLabel(index), ": scale must have 3 elements"));
            finite(node.scale, "scale");
            t.scale = vec3(node.scale[0], node.scale[1], node.scale[2]);
        }
        return t;
    }

    // ---- mesh instances ---------------------------------------------------------
    void stageInstance(int nodeIndex, StagedNode& out) {
        const tg::Node& node = m_.nodes[static_cast<std::size_t>(nodeIndex)];
        BaseMesh& base = baseMesh(node.mesh);
        if (base.asset.geometries.empty()) return;  // points/lines only: nothing to trace
        const bool skinned = node.skin >= 0;
        if (skinned) {
            if (!base.skinnable)
                fail_(cat(nodeLabel(nodeIndex), " has a skin but ", meshLabel(node.mesh),
                          " lacks JOINTS_0/WEIGHTS_0 in some primitive"));
            const StagedSkin& skin = stageSkin(node.skin);
            if (base.jointsNeeded > skin.jointNodes.size())
                fail_(cat(meshLabel(node.mesh), " uses joint index ", base.jointsNeeded - 1, " but skin ", node.skin,
                          " of ", nodeLabel(nodeIndex), " has ", skin.jointNodes.size(), " joints"));
            out.skin = node.skin;
        }
        if (base.targetCount > 0) {
            std::vector<float> weights(base.targetCount, 0.f);
            const std::vector<double>* source = !node.weights.empty() ? &node.weights
                                                : !m_.meshes[static_cast<std::size_t>(node.mesh)].weights.empty()
                                                    ? &m_.meshes[static_cast<std::size_t>(node.mesh)].weights
                                                    : nullptr;
            if (source) {
                if (source->size() != base.targetCount)
                    fail_(cat(nodeLabel(nodeIndex), ": ", source->size(), " morph weights for ", base.targetCount,
                              " morph targets of ", meshLabel(node.mesh)));
                for (std::size_t i = 0; i < weights.size(); ++i) {
                    if (!std::isfinite((*source)[i])) fail_(cat(nodeLabel(nodeIndex), ": non-finite morph weight"));
                    weights[i] = static_cast<float>((*source)[i]);
                }
            }
            out.morph = MorphWeights{std::move(weights)};
        } else if (!node.weights.empty()) {
            fail_(cat(nodeLabel(nodeIndex), " has morph weights but ", meshLabel(node.mesh), " has no morph targets"));
        }

        const bool deformable = skinned || base.targetCount > 0;
        if (!deformable) {
            if (base.rigidVariant < 0) {
                MeshAsset rigid = base.asset;
                for (Geometry& g : rigid.geometries) {
                    g.joints.clear();
                    g.weights.clear();
                }
                base.rigidVariant = static_cast<int>(s_.meshes.size());
                s_.meshes.push_back(std::move(rigid));
            }
            out.mesh = base.rigidVariant;
            return;
        }
        // Deformation writes into the asset: every deformable instance owns one.
        MeshAsset copy = base.asset;
        for (Geometry& g : copy.geometries) {
            if (!skinned) {
                g.joints.clear();
                g.weights.clear();
            }
            g.restPositions = g.positions;
            g.restNormals = g.normals;
        }
        out.mesh = static_cast<int>(s_.meshes.size());
        s_.meshes.push_back(std::move(copy));
    }

    const StagedSkin& stageSkin(int index) {
        std::optional<StagedSkin>& slot = s_.skins[static_cast<std::size_t>(index)];
        if (slot) return *slot;
        const tg::Skin& skin = m_.skins[static_cast<std::size_t>(index)];
        const std::string label = skin.name.empty() ? cat("skin ", index) : cat("skin ", index, " '", skin.name, "'");
        if (skin.joints.empty()) fail_(cat(label, " has no joints"));
        StagedSkin out;
        for (int j : skin.joints) {
            checkIndex(j, m_.nodes, "joint node", label);
            out.jointNodes.push_back(j);
        }
        if (skin.skeleton >= 0) checkIndex(skin.skeleton, m_.nodes, "skeleton node", label);
        out.inverseBind.assign(skin.joints.size(), mat4(1.f));
        if (skin.inverseBindMatrices >= 0) {
            const std::string what = cat("inverseBindMatrices of ", label);
            const AccessorView v = view(skin.inverseBindMatrices, what, {TINYGLTF_TYPE_MAT4}, {{kFloat}}, "MAT4 float");
            if (v.count < skin.joints.size())
                fail_(cat("accessor ", v.index, " (", what, ") has ", v.count, " matrices for ", skin.joints.size(),
                          " joints"));
            const std::vector<float> f = readFloats(v, what);
            for (std::size_t j = 0; j < skin.joints.size(); ++j)
                for (int c = 0; c < 4; ++c)
                    for (int r = 0; r < 4; ++r) out.inverseBind[j][c][r] = f[j * 16 + static_cast<std::size_t>(c * 4 + r)];
        }
        slot = std::move(out);
        return *slot;
    }

    BaseMesh& baseMesh(int meshIndex) {
        auto& slot = baseMeshes_[static_cast<std::size_t>(meshIndex)];
        if (!slot) slot = convertMesh(meshIndex);
        return *slot;
    }

    BaseMesh convertMesh(int meshIndex) {
        const tg::Mesh& mesh = m_.meshes[static_cast<std::size_t>(meshIndex)];
        const std::string label = meshLabel(meshIndex);
        if (mesh.primitives.empty()) fail_(cat(label, " has no primitives"));
        BaseMesh out;
        out.asset.name = mesh.name.empty() ? cat("mesh ", meshIndex) : mesh.name;
        out.targetCount = mesh.primitives.front().targets.size();
        out.skinnable = true;
        for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
            const tg::Primitive& prim = mesh.primitives[p];
            const std::string where = cat(label, " primitive ", p);
            if (prim.targets.size() != out.targetCount)
                fail_(cat(where, " has ", prim.targets.size(), " morph targets, primitive 0 has ", out.targetCount));
            const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
            if (mode > TINYGLTF_MODE_TRIANGLE_FAN) fail_(cat(where, ": invalid primitive mode ", mode));
            if (mode < TINYGLTF_MODE_TRIANGLES) {
                // Points and lines: validated like triangles, then left out
                // (a ray tracer renders triangles); counted for the warning.
                const int pos = attribute(prim, "POSITION");
                if (pos < 0) fail_(cat(where, " has no POSITION attribute"));
                const std::size_t n = readPositions(pos, cat("POSITION of ", where)).size();
                if (prim.indices >= 0) readIndices(prim.indices, cat("indices of ", where), n);
                ++(mode == TINYGLTF_MODE_POINTS ? s_.skippedPointPrimitives : s_.skippedLinePrimitives);
                continue;
            }
            bool hasSkinAttributes = false;
            out.asset.geometries.push_back(convertPrimitive(prim, where, hasSkinAttributes, out.jointsNeeded));
            out.skinnable = out.skinnable && hasSkinAttributes;
        }
        if (!mesh.weights.empty() && mesh.weights.size() != out.targetCount)
            fail_(cat(label, " has ", mesh.weights.size(), " default weights for ", out.targetCount, " morph targets"));
        return out;
    }

    static int attribute(const tg::Primitive& prim, const char* name) {
        const auto it = prim.attributes.find(name);
        return it == prim.attributes.end() ? -1 : it->second;
    }
    static int attribute(const std::map<std::string, int>& attrs, const char* name) {
        const auto it = attrs.find(name);
        return it == attrs.end() ? -1 : it->second;
    }

    std::vector<vec3> readVec3(int accessor, const std::string& what, std::size_t expectedCount,
                               const std::vector<Format>& formats, const char* expected) {
        const AccessorView v = view(accessor, what, {TINYGLTF_TYPE_VEC3}, formats, expected);
        requireCount(v, what, expectedCount);
        const std::vector<float> f = readFloats(v, what);
        std::vector<vec3> out(v.count);
        for (std::size_t i = 0; i < v.count; ++i) out[i] = vec3(f[3 * i], f[3 * i + 1], f[3 * i + 2]);
        return out;
    }

    // Vertex attribute formats: glTF 2.0 core, widened by KHR_mesh_quantization
    // when the file uses it (normalized or integer positions; integer
    // normals and texture coordinates).
    std::vector<vec3> readPositions(int accessor, const std::string& what) {
        if (!quantized_) return readVec3(accessor, what, 0, {{kFloat}}, "VEC3 float");
        return readVec3(accessor, what, 0,
                        {{kFloat}, {kByte, false, true}, {kUByte, false, true}, {kShort, false, true},
                         {kUShort, false, true}},
                        "VEC3 float or (KHR_mesh_quantization) byte/short");
    }
    std::vector<vec3> readNormals(int accessor, const std::string& what, std::size_t n) {
        if (!quantized_) return readVec3(accessor, what, n, {{kFloat}}, "VEC3 float");
        return readVec3(accessor, what, n, {{kFloat}, {kByte, true}, {kShort, true}},
                        "VEC3 float or (KHR_mesh_quantization) normalized byte/short");
    }
    std::vector<vec3> readPositionDeltas(int accessor, const std::string& what, std::size_t n) {
        if (!quantized_) return readVec3(accessor, what, n, {{kFloat}}, "VEC3 float");
        return readVec3(accessor, what, n, {{kFloat}, {kByte, false, true}, {kShort, false, true}},
                        "VEC3 float or (KHR_mesh_quantization) byte/short");
    }

    // Index accessor, every index checked against the vertex count.
    std::vector<std::uint32_t> readIndices(int accessor, const std::string& what, std::size_t n) {
        const AccessorView v = view(accessor, what, {TINYGLTF_TYPE_SCALAR},
                                    {{kUByte, false, true}, {kUShort, false, true}, {kUInt, false, true}},
                                    "SCALAR unsigned byte/short/int");
        std::vector<std::uint32_t> out = readUInts(v);
        for (std::size_t i = 0; i < out.size(); ++i)
            if (out[i] >= n)
                fail_(cat("accessor ", v.index, " (", what, "): index ", out[i], " at position ", i,
                          " is out of range (", n, " vertices)"));
        return out;
    }

    // KHR_draco_mesh_compression: decodes the primitive's Draco buffer; its
    // attributes stand in for the accessors they name (in decoded_, which
    // view() reads) and its faces are the primitive's indices.
    std::optional<std::vector<std::uint32_t>> decodeDraco(const tg::Primitive& prim, const std::string& where) {
        decoded_.clear();
        const auto it = prim.extensions.find("KHR_draco_mesh_compression");
        if (it == prim.extensions.end()) return std::nullopt;
        const std::string label = cat(where, " (KHR_draco_mesh_compression)");
        const tg::Value& ext = it->second;
        const int bufferView = ext.Get("bufferView").GetNumberAsInt();
        const tg::Value& attrs = ext.Get("attributes");
        std::vector<compression::DracoAttributeRequest> requests;
        std::vector<int> accessors;
        for (const std::string& semantic : attrs.Keys()) {
            const int accessor = attribute(prim, semantic.c_str());
            if (accessor < 0) continue;  // not used by the primitive: ignored
            checkIndex(accessor, m_.accessors, "accessor", cat(label, " ", semantic));
            const tg::Accessor& acc = m_.accessors[static_cast<std::size_t>(accessor)];
            if (componentCount(acc.type) == 0 || componentSize(acc.componentType) == 0)
                fail_(cat("accessor ", accessor, " (", semantic, " of ", where, "): invalid type or component type"));
            const double id = attrs.Get(semantic).GetNumberAsDouble();
            requests.push_back({static_cast<std::uint32_t>(id), acc.componentType, componentCount(acc.type)});
            accessors.push_back(accessor);
        }
        std::size_t length = 0;
        const unsigned char* bytes = bufferViewBytes(bufferView, length, label);
        compression::DracoMesh mesh = compression::decodeDracoMesh(bytes, length, requests);
        if (!mesh.error.empty()) fail_(cat(label, ": ", mesh.error));
        for (std::size_t i = 0; i < accessors.size(); ++i) {
            const tg::Accessor& acc = m_.accessors[static_cast<std::size_t>(accessors[i])];
            if (acc.count != mesh.points)
                fail_(cat(label, ": decodes ", mesh.points, " points but accessor ", accessors[i], " declares ",
                          acc.count));
            decoded_[accessors[i]] = std::move(mesh.attributes[i]);
        }
        if (prim.indices >= 0) {
            checkIndex(prim.indices, m_.accessors, "accessor", cat("indices of ", label));
            const std::size_t declared = m_.accessors[static_cast<std::size_t>(prim.indices)].count;
            if (declared != mesh.indices.size())
                fail_(cat(label, ": decodes ", mesh.indices.size(), " indices but accessor ", prim.indices,
                          " declares ", declared));
        }
        return std::move(mesh.indices);
    }

    void requireCount(const AccessorView& v, const std::string& what, std::size_t expected) const {
        if (expected != 0 && v.count != expected)
            fail_(cat("accessor ", v.index, " (", what, ") has ", v.count, " elements, POSITION has ", expected));
    }

    Geometry convertPrimitive(const tg::Primitive& prim, const std::string& where, bool& hasSkinAttributes,
                              std::uint32_t& jointsNeeded) {
        Geometry g;
        const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
        std::optional<std::vector<std::uint32_t>> dracoIndices = decodeDraco(prim, where);

        const int posAccessor = attribute(prim, "POSITION");
        if (posAccessor < 0) fail_(cat(where, " has no POSITION attribute"));
        g.positions = readPositions(posAccessor, cat("POSITION of ", where));
        const std::size_t n = g.positions.size();

        const int normalAccessor = attribute(prim, "NORMAL");
        if (normalAccessor >= 0) g.normals = readNormals(normalAccessor, cat("NORMAL of ", where), n);

        if (const int uvAccessor = attribute(prim, "TEXCOORD_0"); uvAccessor >= 0) {
            const std::string what = cat("TEXCOORD_0 of ", where);
            const AccessorView v =
                quantized_ ? view(uvAccessor, what, {TINYGLTF_TYPE_VEC2},
                                  {{kFloat}, {kByte, false, true}, {kUByte, false, true}, {kShort, false, true},
                                   {kUShort, false, true}},
                                  "VEC2 float or (KHR_mesh_quantization) byte/short")
                           : view(uvAccessor, what, {TINYGLTF_TYPE_VEC2}, {{kFloat}, {kUByte, true}, {kUShort, true}},
                                  "VEC2 float or normalized unsigned byte/short");
            requireCount(v, what, n);
            const std::vector<float> f = readFloats(v, what);
            g.uv0.resize(n);
            for (std::size_t i = 0; i < n; ++i) g.uv0[i] = vec2(f[2 * i], f[2 * i + 1]);
        }

        const int jointsAccessor = attribute(prim, "JOINTS_0");
        const int weightsAccessor = attribute(prim, "WEIGHTS_0");
        if ((jointsAccessor >= 0) != (weightsAccessor >= 0))
            fail_(cat(where, " has only one of JOINTS_0 and WEIGHTS_0"));
        hasSkinAttributes = jointsAccessor >= 0;
        if (hasSkinAttributes) {
            const std::string jWhat = cat("JOINTS_0 of ", where), wWhat = cat("WEIGHTS_0 of ", where);
            const AccessorView jv = view(jointsAccessor, jWhat, {TINYGLTF_TYPE_VEC4},
                                         {{kUByte, false, true}, {kUShort, false, true}}, "VEC4 unsigned byte/short");
            requireCount(jv, jWhat, n);
            const AccessorView wv = view(weightsAccessor, wWhat, {TINYGLTF_TYPE_VEC4},
                                         {{kFloat}, {kUByte, true}, {kUShort, true}},
                                         "VEC4 float or normalized unsigned byte/short");
            requireCount(wv, wWhat, n);
            const std::vector<std::uint32_t> j = readUInts(jv);
            const std::vector<float> w = readFloats(wv, wWhat);
            g.joints.resize(n);
            g.weights.resize(n);
            for (std::size_t i = 0; i < n; ++i) {
                vec4 wi(w[4 * i], w[4 * i + 1], w[4 * i + 2], w[4 * i + 3]);
                const glm::uvec4 ji(j[4 * i], j[4 * i + 1], j[4 * i + 2], j[4 * i + 3]);
                if (wi.x < 0.f || wi.y < 0.f || wi.z < 0.f || wi.w < 0.f)
                    fail_(cat("accessor ", wv.index, " (", wWhat, ") has a negative weight at vertex ", i));
                const float sum = wi.x + wi.y + wi.z + wi.w;
                if (!(sum > 0.f) || !std::isfinite(sum)) wi = vec4(1.f, 0.f, 0.f, 0.f);
                else wi /= sum;
                for (int k = 0; k < 4; ++k)
                    if (wi[k] > 0.f) jointsNeeded = std::max(jointsNeeded, ji[k] + 1u);
                g.joints[i] = ji;
                g.weights[i] = wi;
            }
        }

        // Indices: validated against the vertex count, then converted to a list.
        std::vector<std::uint32_t> source;
        if (dracoIndices) {
            source = std::move(*dracoIndices);  // checked against the decoded point count
        } else if (prim.indices >= 0) {
            source = readIndices(prim.indices, cat("indices of ", where), n);
        } else {
            source.resize(n);
            for (std::size_t i = 0; i < n; ++i) source[i] = static_cast<std::uint32_t>(i);
        }
        const std::size_t k = source.size();
        if (mode == TINYGLTF_MODE_TRIANGLES) {
            if (k % 3 != 0 || k == 0)
                fail_(cat(where, ": ", k, prim.indices >= 0 ? " indices" : " vertices",
                          " do not form whole triangles (not a multiple of 3)"));
            g.indices = std::move(source);
        } else {
            if (k < 3) fail_(cat(where, ": a triangle strip/fan needs at least 3 vertices, got ", k));
            g.indices.reserve(3 * (k - 2));
            for (std::size_t i = 0; i + 2 < k; ++i) {
                if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
                    // glTF 2.0 §3.7.2.1: p_i = {v_i, v_(i+(1+i%2)), v_(i+(2-i%2))}
                    const std::size_t odd = i % 2;
                    g.indices.insert(g.indices.end(), {source[i], source[i + 1 + odd], source[i + 2 - odd]});
                } else {
                    // Fan: p_i = {v_(i+1), v_(i+2), v_0}
                    g.indices.insert(g.indices.end(), {source[i + 1], source[i + 2], source[0]});
                }
            }
        }

        // Normals: generated when missing; given ones normalised, zero-length
        // ones replaced by generated normals per vertex.
        if (g.normals.empty()) {
            g.normals = generateVertexNormals(g.positions, g.indices);
        } else {
            std::vector<vec3> generated;
            for (std::size_t i = 0; i < n; ++i) {
                const float len = glm::length(g.normals[i]);
                if (len > 1e-20f && std::isfinite(len)) {
                    g.normals[i] /= len;
                } else {
                    if (generated.empty()) generated = generateVertexNormals(g.positions, g.indices);
                    g.normals[i] = generated[i];
                }
            }
        }

        // Morph targets (TANGENT and other attributes are ignored).
        for (std::size_t t = 0; t < prim.targets.size(); ++t) {
            const auto& target = prim.targets[t];
            MorphTarget mt;
            if (const int a = attribute(target, "POSITION"); a >= 0)
                mt.positionDeltas = readPositionDeltas(a, cat("POSITION of morph target ", t, " of ", where), n);
            if (const int a = attribute(target, "NORMAL"); a >= 0)
                mt.normalDeltas = readNormals(a, cat("NORMAL of morph target ", t, " of ", where), n);
            g.morphTargets.push_back(std::move(mt));
        }

        if (prim.material >= 0) {
            checkIndex(prim.material, m_.materials, "material", where);
            g.material = static_cast<MaterialId>(localMaterial(prim.material));
        } else {
            g.material = static_cast<MaterialId>(defaultMaterial());
        }
        decoded_.clear();
        return g;
    }

    // ---- accessors --------------------------------------------------------------
    // Returns the bytes of a bufferView after checking it lies in its buffer.
    const unsigned char* bufferViewBytes(int index, std::size_t& length, const std::string& user) const {
        checkIndex(index, m_.bufferViews, "bufferView", user);
        const tg::BufferView& bv = m_.bufferViews[static_cast<std::size_t>(index)];
        checkIndex(bv.buffer, m_.buffers, "buffer", cat("bufferView ", index));
        const std::vector<unsigned char>& data = m_.buffers[static_cast<std::size_t>(bv.buffer)].data;
        if (bv.byteLength == 0 || bv.byteOffset > data.size() || bv.byteLength > data.size() - bv.byteOffset)
            fail_(cat("bufferView ", index, " (byteOffset ", bv.byteOffset, ", byteLength ", bv.byteLength,
                      ") exceeds buffer ", bv.buffer, " (", data.size(), " bytes)"));
        length = bv.byteLength;
        return data.data() + bv.byteOffset;
    }

    AccessorView view(int index, const std::string& what, std::initializer_list<int> types,
                      const std::vector<Format>& formats, const char* expected) const {
        checkIndex(index, m_.accessors, "accessor", what);
        const tg::Accessor& acc = m_.accessors[static_cast<std::size_t>(index)];
        const std::string label = cat("accessor ", index, " (", what, ")");
        bool typeOk = std::find(types.begin(), types.end(), acc.type) != types.end();
        bool formatOk = false;
        for (const Format& f : formats)
            if (f.componentType == acc.componentType &&
                (f.componentType == kFloat || f.anyNorm || f.normalized == acc.normalized))
                formatOk = true;
        if (!typeOk || !formatOk)
            fail_(cat(label, ": expected ", expected, ", got ", typeName(acc.type), " ",
                      componentTypeName(acc.componentType, acc.normalized)));

        AccessorView v;
        v.index = index;
        v.acc = &acc;
        v.components = componentCount(acc.type);
        v.componentBytes = componentSize(acc.componentType);
        v.count = acc.count;
        if (v.count == 0) fail_(cat(label, ": count must be at least 1"));
        const std::size_t elementBytes = static_cast<std::size_t>(v.components * v.componentBytes);

        if (const auto decoded = decoded_.find(index); decoded != decoded_.end()) {
            v.data = decoded->second.data();  // Draco: count elements, tightly packed
            v.stride = elementBytes;
        } else if (acc.bufferView >= 0) {
            std::size_t viewLength = 0;
            const unsigned char* bytes = bufferViewBytes(acc.bufferView, viewLength, label);
            const std::size_t declaredStride = m_.bufferViews[static_cast<std::size_t>(acc.bufferView)].byteStride;
            v.stride = declaredStride != 0 ? declaredStride : elementBytes;
            if (v.stride < elementBytes)
                fail_(cat(label, ": byteStride ", v.stride, " is smaller than the element size ", elementBytes));
            // byteOffset + stride * (count - 1) + elementSize <= bufferView length, overflow-free.
            if (acc.byteOffset > viewLength || elementBytes > viewLength - acc.byteOffset ||
                (v.count - 1) > (viewLength - acc.byteOffset - elementBytes) / v.stride)
                fail_(cat(label, ": ", v.count, " elements at byteOffset ", acc.byteOffset, " with stride ", v.stride,
                          " exceed bufferView ", acc.bufferView, " (", viewLength, " bytes)"));
            v.data = bytes + acc.byteOffset;
        } else if (v.count > kMaxUnbackedAccessorElements) {
            fail_(cat(label, ": ", v.count, " elements without a bufferView (limit ", kMaxUnbackedAccessorElements, ")"));
        }

        if (acc.sparse.isSparse) {
            const int sc = acc.sparse.count;
            if (sc < 1 || static_cast<std::size_t>(sc) > v.count)
                fail_(cat(label, ": sparse count ", sc, " must be in [1, ", v.count, "]"));
            const auto sparseCount = static_cast<std::size_t>(sc);
            const int ict = acc.sparse.indices.componentType;
            if (ict != kUByte && ict != kUShort && ict != kUInt)
                fail_(cat(label, ": sparse indices must be unsigned byte/short/int"));
            const auto indexBytes = static_cast<std::size_t>(componentSize(ict));
            std::size_t length = 0;
            const unsigned char* ib = bufferViewBytes(acc.sparse.indices.bufferView, length, cat(label, " sparse indices"));
            const std::size_t ioff = static_cast<std::size_t>(std::max(acc.sparse.indices.byteOffset, 0));
            if (ioff > length || sparseCount > (length - ioff) / indexBytes)
                fail_(cat(label, ": sparse indices exceed bufferView ", acc.sparse.indices.bufferView));
            const unsigned char* vb = bufferViewBytes(acc.sparse.values.bufferView, length, cat(label, " sparse values"));
            const std::size_t voff = static_cast<std::size_t>(std::max(acc.sparse.values.byteOffset, 0));
            if (voff > length || sparseCount > (length - voff) / elementBytes)
                fail_(cat(label, ": sparse values exceed bufferView ", acc.sparse.values.bufferView));
            v.sparseIndices.resize(sparseCount);
            for (std::size_t i = 0; i < sparseCount; ++i) {
                const std::uint32_t target = readUInt(ib + ioff + i * indexBytes, ict);
                if (target >= v.count || (i > 0 && target <= v.sparseIndices[i - 1]))
                    fail_(cat(label, ": sparse indices must be strictly increasing and < ", v.count));
                v.sparseIndices[i] = target;
            }
            v.sparseValues = vb + voff;
        }
        return v;
    }

    template <class T, class Read>
    static std::vector<T> gather(const AccessorView& v, Read read) {
        const auto nc = static_cast<std::size_t>(v.components);
        const auto cs = static_cast<std::size_t>(v.componentBytes);
        std::vector<T> out(v.count * nc, T(0));
        if (v.data)
            for (std::size_t i = 0; i < v.count; ++i)
                for (std::size_t c = 0; c < nc; ++c) out[i * nc + c] = read(v.data + i * v.stride + c * cs);
        for (std::size_t k = 0; k < v.sparseIndices.size(); ++k)
            for (std::size_t c = 0; c < nc; ++c)
                out[v.sparseIndices[k] * nc + c] = read(v.sparseValues + (k * nc + c) * cs);
        return out;
    }

    // Reads as float (normalized integers converted per the spec); all values must be finite.
    std::vector<float> readFloats(const AccessorView& v, const std::string& what) const {
        const int ct = v.acc->componentType;
        const bool normalized = v.acc->normalized;
        std::vector<float> out = gather<float>(v, [&](const unsigned char* p) { return readFloat(p, ct, normalized); });
        for (std::size_t i = 0; i < out.size(); ++i)
            if (!std::isfinite(out[i]))
                fail_(cat("accessor ", v.index, " (", what, ") contains a non-finite value at element ",
                          i / static_cast<std::size_t>(v.components)));
        return out;
    }
    static std::vector<std::uint32_t> readUInts(const AccessorView& v) {
        const int ct = v.acc->componentType;
        return gather<std::uint32_t>(v, [&](const unsigned char* p) { return readUInt(p, ct); });
    }

    // ---- materials and textures ----------------------------------------------------
    int defaultMaterial() {
        if (defaultMaterial_ < 0) {
            defaultMaterial_ = static_cast<int>(s_.materials.size());
            Material m;
            m.name = "default";
            s_.materials.push_back(m);
        }
        return defaultMaterial_;
    }

    int localMaterial(int index) {
        int& slot = materialSlot_[static_cast<std::size_t>(index)];
        if (slot < 0) {
            Material m = convertMaterial(index);
            slot = static_cast<int>(s_.materials.size());
            s_.materials.push_back(std::move(m));
        }
        return slot;
    }

    float factor(double v, float lo, float hi, const std::string& what) const {
        if (!std::isfinite(v)) fail_(cat(what, " is not finite"));
        return std::clamp(static_cast<float>(std::clamp(v, -3.0e38, 3.0e38)), lo, hi);
    }

    // Number `key` of material extension `ext`, if present.
    std::optional<double> extensionNumber(const tg::Material& mat, const char* ext, const char* key,
                                          const std::string& label) const {
        const auto it = mat.extensions.find(ext);
        if (it == mat.extensions.end() || !it->second.IsObject() || !it->second.Has(key)) return std::nullopt;
        const tg::Value& v = it->second.Get(key);
        if (!v.IsNumber()) fail_(cat(label, ": ", ext, ".", key, " must be a number"));
        return v.GetNumberAsDouble();
    }

    Material convertMaterial(int index) {
        const tg::Material& mat = m_.materials[static_cast<std::size_t>(index)];
        const std::string label = materialLabel(index);
        Material out;
        out.name = mat.name.empty() ? cat("material ", index) : mat.name;
        const tg::PbrMetallicRoughness& pbr = mat.pbrMetallicRoughness;
        if (pbr.baseColorFactor.size() != 4) fail_(cat(label, ": baseColorFactor must have 4 elements"));
        for (int c = 0; c < 4; ++c)
            out.baseColor[c] = factor(pbr.baseColorFactor[static_cast<std::size_t>(c)], 0.f, 1.f,
                                      cat(label, " baseColorFactor"));
        out.metallic = factor(pbr.metallicFactor, 0.f, 1.f, cat(label, " metallicFactor"));
        out.roughness = factor(pbr.roughnessFactor, 0.f, 1.f, cat(label, " roughnessFactor"));

        // Every referenced texture must exist, even those we do not use.
        const std::pair<int, const char*> refs[] = {{pbr.baseColorTexture.index, "baseColorTexture"},
                                                    {pbr.metallicRoughnessTexture.index, "metallicRoughnessTexture"},
                                                    {mat.normalTexture.index, "normalTexture"},
                                                    {mat.occlusionTexture.index, "occlusionTexture"},
                                                    {mat.emissiveTexture.index, "emissiveTexture"}};
        for (const auto& [tex, name] : refs)
            if (tex >= 0) checkIndex(tex, m_.textures, "texture", cat(label, " ", name));
        if (pbr.baseColorTexture.index >= 0 && pbr.baseColorTexture.texCoord == 0)
            out.baseColorTexture = localTexture(pbr.baseColorTexture.index);

        if (!mat.emissiveFactor.empty()) {
            if (mat.emissiveFactor.size() != 3) fail_(cat(label, ": emissiveFactor must have 3 elements"));
            for (int c = 0; c < 3; ++c)
                out.emissive[c] = factor(mat.emissiveFactor[static_cast<std::size_t>(c)], 0.f, 1.f,
                                         cat(label, " emissiveFactor"));
        }
        if (const auto s = extensionNumber(mat, "KHR_materials_emissive_strength", "emissiveStrength", label))
            out.emissive *= factor(*s, 0.f, 3.0e38f, cat(label, " emissiveStrength"));

        if (mat.alphaMode == "OPAQUE") out.alphaMode = AlphaMode::Opaque;
        else if (mat.alphaMode == "MASK") out.alphaMode = AlphaMode::Mask;
        else if (mat.alphaMode == "BLEND") out.alphaMode = AlphaMode::Blend;
        else fail_(cat(label, ": unknown alphaMode '", mat.alphaMode, "'"));
        out.alphaCutoff = factor(mat.alphaCutoff, 0.f, 1.f, cat(label, " alphaCutoff"));
        out.doubleSided = mat.doubleSided;

        if (const auto t = extensionNumber(mat, "KHR_materials_transmission", "transmissionFactor", label))
            out.transmission = factor(*t, 0.f, 1.f, cat(label, " transmissionFactor"));
        if (const auto ior = extensionNumber(mat, "KHR_materials_ior", "ior", label))
            // The extension allows 0 ("infinite" ior); we clamp to physical values.
            out.ior = factor(*ior, 1.f, 10.f, cat(label, " ior"));
        if (const auto d = extensionNumber(mat, "KHR_materials_volume", "attenuationDistance", label)) {
            const float dist = factor(*d, 0.f, kInfinity, cat(label, " attenuationDistance"));
            out.attenuationDistance = dist > 0.f ? dist : kInfinity;  // <= 0 is invalid: no attenuation
        }
        if (const auto it = mat.extensions.find("KHR_materials_volume");
            it != mat.extensions.end() && it->second.IsObject() && it->second.Has("attenuationColor")) {
            const tg::Value& c = it->second.Get("attenuationColor");
            if (!c.IsArray() || c.ArrayLen() != 3) fail_(cat(label, ": attenuationColor must have 3 numbers"));
            for (int i = 0; i < 3; ++i) {
                if (!c.Get(i).IsNumber()) fail_(cat(label, ": attenuationColor must have 3 numbers"));
                out.attenuationColor[i] = factor(c.Get(i).GetNumberAsDouble(), 0.f, 1.f, cat(label, " attenuationColor"));
            }
        }
        return out;
    }

    // Local texture index for a glTF texture, or kNoTexture when it has no usable image.
    std::uint32_t localTexture(int textureIndex) {
        const tg::Texture& tex = m_.textures[static_cast<std::size_t>(textureIndex)];
        if (tex.sampler >= 0) checkIndex(tex.sampler, m_.samplers, "sampler", cat("texture ", textureIndex));
        if (tex.source < 0) return kNoTexture;  // e.g. only an extension source (KTX2, WebP)
        checkIndex(tex.source, m_.images, "image", cat("texture ", textureIndex));
        int& slot = imageSlot_[static_cast<std::size_t>(tex.source)];
        if (slot == -2) {
            std::optional<Texture> t = convertImage(tex.source);
            slot = t ? static_cast<int>(s_.textures.size()) : -1;
            if (t) s_.textures.push_back(std::move(*t));
        }
        return slot < 0 ? kNoTexture : static_cast<std::uint32_t>(slot);
    }

    std::optional<Texture> convertImage(int index) const {
        const tg::Image& img = m_.images[static_cast<std::size_t>(index)];
        if (img.image.empty() || img.width <= 0 || img.height <= 0) return std::nullopt;
        if (img.component < 1 || img.component > 4 || (img.bits != 8 && img.bits != 16)) return std::nullopt;
        const auto w = static_cast<std::size_t>(img.width), h = static_cast<std::size_t>(img.height);
        const auto comp = static_cast<std::size_t>(img.component), bytes = static_cast<std::size_t>(img.bits / 8);
        if (img.image.size() != w * h * comp * bytes)
            fail_(cat("image ", index, ": decoded data has ", img.image.size(), " bytes, expected ", w * h * comp * bytes));
        Texture t;
        t.name = img.name.empty() ? (img.uri.empty() || img.uri.rfind("data:", 0) == 0 ? cat("image ", index) : img.uri)
                                  : img.name;
        t.width = img.width;
        t.height = img.height;
        t.srgb = true;  // only base-color textures are loaded
        t.rgba8.resize(w * h * 4);
        const unsigned char* src = img.image.data();
        // 16-bit samples are stored in native (little-endian) order: take the high byte.
        auto sample = [&](std::size_t px, std::size_t c) -> std::uint8_t {
            return bytes == 1 ? src[px * comp + c] : src[(px * comp + c) * 2 + 1];
        };
        for (std::size_t px = 0; px < w * h; ++px) {
            std::uint8_t* d = &t.rgba8[px * 4];
            switch (comp) {
                case 1: d[0] = d[1] = d[2] = sample(px, 0); d[3] = 255; break;
                case 2: d[0] = d[1] = d[2] = sample(px, 0); d[3] = sample(px, 1); break;
                case 3: d[0] = sample(px, 0); d[1] = sample(px, 1); d[2] = sample(px, 2); d[3] = 255; break;
                default: for (std::size_t c = 0; c < 4; ++c) d[c] = sample(px, c); break;
            }
        }
        return t;
    }

    // ---- cameras and lights -----------------------------------------------------------
    Camera convertCamera(int index) const {
        const tg::Camera& cam = m_.cameras[static_cast<std::size_t>(index)];
        const std::string label = cam.name.empty() ? cat("camera ", index) : cat("camera ", index, " '", cam.name, "'");
        auto finite = [&](double v, const char* what) {
            if (!std::isfinite(v) || std::abs(v) > 3.0e38) fail_(cat(label, ": ", what, " is not finite"));
            return static_cast<float>(v);
        };
        Camera out;
        if (cam.type == "perspective") {
            const tg::PerspectiveCamera& p = cam.perspective;
            const float yfov = finite(p.yfov, "yfov"), znear = finite(p.znear, "znear");
            const float zfar = finite(p.zfar, "zfar"), aspect = finite(p.aspectRatio, "aspectRatio");
            if (!(yfov > 0.f)) fail_(cat(label, ": yfov must be > 0"));
            if (!(znear > 0.f)) fail_(cat(label, ": znear must be > 0"));
            if (zfar != 0.f && !(zfar > znear)) fail_(cat(label, ": zfar must be greater than znear"));
            if (aspect < 0.f) fail_(cat(label, ": aspectRatio must be > 0"));
            out.yfov = std::min(yfov, kPi - 1e-3f);
            out.znear = znear;
            out.zfar = zfar == 0.f ? kInfiniteFar : zfar;  // glTF: no zfar = infinite projection
            out.aspectRatio = aspect;
        } else if (cam.type == "orthographic") {
            // Approximated as perspective: Camera has no orthographic mode.
            const tg::OrthographicCamera& o = cam.orthographic;
            const float xmag = finite(o.xmag, "xmag"), ymag = finite(o.ymag, "ymag");
            const float znear = finite(o.znear, "znear"), zfar = finite(o.zfar, "zfar");
            if (!(zfar > znear) || znear < 0.f) fail_(cat(label, ": needs 0 <= znear < zfar"));
            out.yfov = 0.8f;
            out.znear = znear > 0.f ? znear : std::min(0.01f, 0.5f * zfar);
            out.zfar = zfar;
            out.aspectRatio = (xmag != 0.f && ymag != 0.f) ? std::abs(xmag / ymag) : 0.f;
        } else {
            fail_(cat(label, ": unknown camera type '", cam.type, "'"));
        }
        return out;
    }

    Light convertLight(int index) const {
        const tg::Light& l = m_.lights[static_cast<std::size_t>(index)];
        const std::string label = l.name.empty() ? cat("light ", index) : cat("light ", index, " '", l.name, "'");
        Light out;
        if (l.type == "point") out.type = LightType::Point;
        else if (l.type == "spot") out.type = LightType::Spot;
        else if (l.type == "directional") out.type = LightType::Directional;
        else fail_(cat(label, ": unknown KHR_lights_punctual type '", l.type, "'"));
        if (!l.color.empty()) {
            if (l.color.size() != 3) fail_(cat(label, ": color must have 3 elements"));
            for (int c = 0; c < 3; ++c)
                out.color[c] = factor(l.color[static_cast<std::size_t>(c)], 0.f, 3.0e38f, cat(label, " color"));
        }
        out.intensity = factor(l.intensity, 0.f, 3.0e38f, cat(label, " intensity"));
        out.range = factor(l.range, 0.f, 3.0e38f, cat(label, " range"));  // 0 = unlimited
        if (out.type == LightType::Spot) {
            const float outer = factor(l.spot.outerConeAngle, 1e-4f, kPi / 2.f, cat(label, " outerConeAngle"));
            out.outerConeAngle = outer;
            out.innerConeAngle = factor(l.spot.innerConeAngle, 0.f, outer, cat(label, " innerConeAngle"));
        }
        return out;
    }

    // ---- animations ---------------------------------------------------------------
    void convertAnimations() {
        for (std::size_t a = 0; a < m_.animations.size(); ++a) {
            const tg::Animation& anim = m_.animations[a];
            const std::string label = anim.name.empty() ? cat("animation ", a) : cat("animation '", anim.name, "'");
            StagedClip clip;
            clip.name = anim.name.empty() ? cat("animation ", a) : anim.name;
            for (std::size_t c = 0; c < anim.channels.size(); ++c) {
                const tg::AnimationChannel& ch = anim.channels[c];
                const std::string where = cat(label, " channel ", c);
                checkIndex(ch.sampler, anim.samplers, "sampler", where);
                if (ch.target_node < 0) continue;  // no target node: ignored per the spec
                checkIndex(ch.target_node, m_.nodes, "node", where);
                StagedChannel out;
                out.gltfNode = ch.target_node;
                out.channel = convertChannel(anim.samplers[static_cast<std::size_t>(ch.sampler)], ch, where);
                if (s_.nodeSlot[static_cast<std::size_t>(ch.target_node)] < 0) continue;  // node not in this scene
                clip.channels.push_back(std::move(out));
            }
            if (!clip.channels.empty()) s_.clips.push_back(std::move(clip));
        }
    }

    AnimationChannel convertChannel(const tg::AnimationSampler& sampler, const tg::AnimationChannel& ch,
                                    const std::string& where) const {
        AnimationChannel out;
        std::size_t components = 0;
        if (ch.target_path == "translation") {
            out.path = AnimationPath::Translation;
            components = 3;
        } else if (ch.target_path == "rotation") {
            out.path = AnimationPath::Rotation;
            components = 4;
        } else if (ch.target_path == "scale") {
            out.path = AnimationPath::Scale;
            components = 3;
        } else if (ch.target_path == "weights") {
            out.path = AnimationPath::Weights;
        } else {
            fail_(cat(where, ": unsupported target path '", ch.target_path, "'"));
        }
        if (out.path == AnimationPath::Weights) {
            const tg::Node& node = m_.nodes[static_cast<std::size_t>(ch.target_node)];
            if (node.mesh < 0 || static_cast<std::size_t>(node.mesh) >= m_.meshes.size() ||
                m_.meshes[static_cast<std::size_t>(node.mesh)].primitives.empty() ||
                m_.meshes[static_cast<std::size_t>(node.mesh)].primitives.front().targets.empty())
                fail_(cat(where, ": animates morph weights of ", nodeLabel(ch.target_node),
                          ", which has no mesh with morph targets"));
            components = m_.meshes[static_cast<std::size_t>(node.mesh)].primitives.front().targets.size();
        }
        out.componentsPerKey = static_cast<std::uint32_t>(components);

        std::size_t valuesPerKey = 1;
        if (sampler.interpolation == "LINEAR") out.interpolation = Interpolation::Linear;
        else if (sampler.interpolation == "STEP") out.interpolation = Interpolation::Step;
        else if (sampler.interpolation == "CUBICSPLINE") {
            out.interpolation = Interpolation::CubicSpline;
            valuesPerKey = 3;
        } else fail_(cat(where, ": unknown interpolation '", sampler.interpolation, "'"));

        const std::string inWhat = cat("input of ", where);
        const AccessorView in = view(sampler.input, inWhat, {TINYGLTF_TYPE_SCALAR}, {{kFloat}}, "SCALAR float");
        out.times = readFloats(in, inWhat);
        for (std::size_t i = 1; i < out.times.size(); ++i)
            if (out.times[i] < out.times[i - 1])
                fail_(cat("accessor ", in.index, " (", inWhat, "): key times decrease at key ", i));

        const std::string outWhat = cat("output of ", where);
        const std::vector<Format> normalizedOrFloat = {
            {kFloat}, {kByte, true}, {kUByte, true}, {kShort, true}, {kUShort, true}};
        AccessorView ov;
        switch (out.path) {
            case AnimationPath::Translation:
            case AnimationPath::Scale:
                ov = view(sampler.output, outWhat, {TINYGLTF_TYPE_VEC3}, {{kFloat}}, "VEC3 float");
                break;
            case AnimationPath::Rotation:
                ov = view(sampler.output, outWhat, {TINYGLTF_TYPE_VEC4}, normalizedOrFloat,
                          "VEC4 float or normalized integer");
                break;
            case AnimationPath::Weights:
                ov = view(sampler.output, outWhat, {TINYGLTF_TYPE_SCALAR}, normalizedOrFloat,
                          "SCALAR float or normalized integer");
                break;
        }
        out.values = readFloats(ov, outWhat);
        const std::size_t expected = out.times.size() * components * valuesPerKey;
        if (out.values.size() != expected)
            fail_(cat(where, ": output accessor ", ov.index, " has ", out.values.size(), " values, expected ", expected,
                      " (", out.times.size(), " keys x ", components, " components",
                      valuesPerKey == 3 ? " x 3 for CUBICSPLINE" : "", ")"));
        return out;
    }

    const tg::Model& m_;
    const Fail& fail_;
    Staged s_;
    std::vector<int> parentOf_;
    std::vector<int> materialSlot_;
    std::vector<int> imageSlot_;
    std::vector<std::optional<BaseMesh>> baseMeshes_;
    int defaultMaterial_ = -1;
    bool quantized_ = false;  // the file uses KHR_mesh_quantization
    std::map<int, std::vector<unsigned char>> decoded_;  // Draco-decoded accessors of the current primitive
};

// ===========================================================================
// Stage 4: commit into the World (cannot fail on bad input).
// ===========================================================================

std::vector<Entity> commit(World& world, Staged&& s, Entity parent) {
    std::vector<TextureId> textureIds;
    textureIds.reserve(s.textures.size());
    for (Texture& t : s.textures) textureIds.push_back(world.addTexture(std::move(t)));

    std::vector<MaterialId> materialIds;
    materialIds.reserve(s.materials.size());
    for (Material& m : s.materials) {
        if (m.baseColorTexture != kNoTexture) m.baseColorTexture = textureIds[m.baseColorTexture];
        materialIds.push_back(world.addMaterial(std::move(m)));
    }

    std::vector<MeshId> meshIds;
    meshIds.reserve(s.meshes.size());
    for (MeshAsset& mesh : s.meshes) {
        for (Geometry& g : mesh.geometries) g.material = materialIds[g.material];
        meshIds.push_back(world.addMesh(std::move(mesh)));
    }

    const bool parentAlive = world.alive(parent);
    std::vector<Entity> entities(s.nodes.size());
    for (std::size_t i = 0; i < s.nodes.size(); ++i) {
        StagedNode& n = s.nodes[i];
        const Entity e = world.create(n.name);
        entities[i] = e;
        world.emplace(e, n.local);
        if (n.parent >= 0) world.emplace(e, Parent{entities[static_cast<std::size_t>(n.parent)]});
        else if (parentAlive) world.emplace(e, Parent{parent});
        if (n.mesh >= 0) world.emplace(e, MeshInstance{meshIds[static_cast<std::size_t>(n.mesh)]});
        if (n.morph) world.emplace(e, std::move(*n.morph));
        if (n.camera) {
            world.emplace(e, *n.camera);
            if (!world.alive(world.activeCamera())) world.setActiveCamera(e);
        }
        if (n.light) world.emplace(e, *n.light);
    }
    auto entityOf = [&](int gltfNode) {
        const int slot = s.nodeSlot[static_cast<std::size_t>(gltfNode)];
        return slot < 0 ? kNullEntity : entities[static_cast<std::size_t>(slot)];
    };
    for (std::size_t i = 0; i < s.nodes.size(); ++i) {
        const StagedNode& n = s.nodes[i];
        if (n.skin < 0) continue;
        const StagedSkin& skin = *s.skins[static_cast<std::size_t>(n.skin)];
        Skin component;
        for (int j : skin.jointNodes) component.joints.push_back(entityOf(j));
        component.inverseBindMatrices = skin.inverseBind;
        world.emplace(entities[i], std::move(component));
    }
    for (StagedClip& c : s.clips) {
        AnimationClip clip;
        clip.name = std::move(c.name);
        for (StagedChannel& ch : c.channels) {
            ch.channel.target = entityOf(ch.gltfNode);
            clip.channels.push_back(std::move(ch.channel));
        }
        world.addAnimation(std::move(clip));
    }

    std::vector<Entity> roots;
    roots.reserve(s.roots.size());
    for (int r : s.roots) roots.push_back(entities[static_cast<std::size_t>(r)]);
    return roots;
}

}  // namespace

std::vector<Entity> loadGltf(World& world, const std::filesystem::path& path, Entity parent) {
    const Fail fail(path.string());
    const std::string ext = lowercase(path.extension().string());
    const bool binary = ext == ".glb";
    if (!binary && ext != ".gltf") fail(cat("not a glTF file (expected the extension .gltf or .glb, got '", ext, "')"));
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) fail("no such file");
    if (!std::filesystem::is_regular_file(path, ec)) fail("not a regular file");

    // Stage 1.
    const Prechecked pre = precheckJson(path, binary, fail);

    // Stage 2.
    tg::Model model;
    {
        tg::TinyGLTF loader;
        std::string err, warn;
        bool ok = false;
        const std::string& text = pre.rewrittenJson;
        const std::string baseDir = path.parent_path().string();
        if (text.size() > 0xffffffffu) fail("file too large");
        try {
            if (!text.empty())
                ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn,
                                                          reinterpret_cast<const unsigned char*>(text.data()),
                                                          static_cast<unsigned int>(text.size()), baseDir)
                            : loader.LoadASCIIFromString(&model, &err, &warn, text.data(),
                                                         static_cast<unsigned int>(text.size()), baseDir);
            else
                ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warn, path.string())
                            : loader.LoadASCIIFromFile(&model, &err, &warn, path.string());
        } catch (const std::exception& e) {
            fail(cat("glTF parser failed: ", firstLineTrimmed(e.what())));
        }
        if (!err.empty()) fail(firstLineTrimmed(err));
        if (!ok) fail("glTF parser failed without a message");
    }
    restoreHiddenIndices(model, pre);
    decodeMeshoptViews(model, pre, fail);

    // Stage 3, then 4.
    Staged staged = GltfConverter(model, fail).convert();
    const std::uint32_t points = staged.skippedPointPrimitives, lines = staged.skippedLinePrimitives;
    std::vector<Entity> roots = commit(world, std::move(staged), parent);
    if (points + lines > 0) {
        LoadReport& report = world.loadReport();
        report.skippedPointPrimitives += points;
        report.skippedLinePrimitives += lines;
        report.warnings.push_back(cat(path.string(), ": skipped ", points, " points and ", lines,
                                      " lines primitive(s) (rtlab traces triangles only)"));
    }
    return roots;
}

}  // namespace rtlab::ecs::load
