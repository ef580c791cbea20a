// Stage 1 of the glTF loader: the structural pre-check of the raw JSON before tinygltf sees it (property
// types, nesting depth, GLB layout, bufferView extents, extensionsRequired), and the JSON rewrites that let
// tinygltf parse EXT_meshopt_compression fallback buffers and Draco-only indices.
#include "gltf_internal.hpp"

#include <rtlab/core/json_nesting.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <set>
#include <string>
#include <tuple>
#include <string_view>
#include <utility>
#include <vector>

namespace rtlab::ecs::load::gltf {
namespace {

using Json = nlohmann::json;

enum class Kind : std::uint8_t {
    UInt,    // integer in [0, kMaxJsonInteger]
    Number,  // finite number
    Bool,
    String,
    Object,  // nested schema
    UIntArray,
    NumberArray,  // optionally of fixed length
    StringArray,
    ObjectArray,   // array of nested schema
    UIntMap,       // object whose values are UInt (primitive attributes)
    UIntMapArray,  // array of UIntMap (morph targets)
};

struct Schema;
struct Prop {
    Prop(const char* n, Kind k, bool req = false, std::size_t len = 0, const Schema* s = nullptr,
         bool nonEmptyArray = false)
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
    static const Schema textureInfo{
        {uintProp("index", true), uintProp("texCoord"), numberProp("scale"), numberProp("strength")}};
    static const Schema transmissionExt{
        {numberProp("transmissionFactor"), objectProp("transmissionTexture", textureInfo)}};
    static const Schema iorExt{{numberProp("ior")}};
    static const Schema volumeExt{{numberProp("thicknessFactor"), objectProp("thicknessTexture", textureInfo),
                                   numberProp("attenuationDistance"), numberArrayProp("attenuationColor", 3)}};
    static const Schema emissiveStrengthExt{{numberProp("emissiveStrength")}};
    static const Schema pbr{{numberArrayProp("baseColorFactor", 4), objectProp("baseColorTexture", textureInfo),
                             numberProp("metallicFactor"), numberProp("roughnessFactor"),
                             objectProp("metallicRoughnessTexture", textureInfo)}};
    static const Schema material{{objectProp("pbrMetallicRoughness", pbr), objectProp("normalTexture", textureInfo),
                                  objectProp("occlusionTexture", textureInfo),
                                  objectProp("emissiveTexture", textureInfo), numberArrayProp("emissiveFactor", 3),
                                  stringProp("alphaMode"), numberProp("alphaCutoff"), boolProp("doubleSided")},
                                 {{"KHR_materials_transmission", &transmissionExt},
                                  {"KHR_materials_ior", &iorExt},
                                  {"KHR_materials_volume", &volumeExt},
                                  {"KHR_materials_emissive_strength", &emissiveStrengthExt}}};
    static const Schema dracoExt{{uintProp("bufferView", true), {"attributes", Kind::UIntMap, true}}};
    static const Schema primitive{{{"attributes", Kind::UIntMap, true},
                                   uintProp("indices"),
                                   uintProp("material"),
                                   uintProp("mode"),
                                   {"targets", Kind::UIntMapArray}},
                                  {{"KHR_draco_mesh_compression", &dracoExt}}};
    static const Schema mesh{{objectArrayProp("primitives", primitive, true, true), numberArrayProp("weights")}};
    static const Schema nodeLight{{uintProp("light", true)}};
    static const Schema node{
        {uintProp("camera"), uintProp("skin"), uintProp("mesh"), uintArrayProp("children"),
         numberArrayProp("matrix", 16), numberArrayProp("rotation", 4), numberArrayProp("scale", 3),
         numberArrayProp("translation", 3), numberArrayProp("weights")},
        {{"KHR_lights_punctual", &nodeLight}}};
    static const Schema scene{{uintArrayProp("nodes")}};
    static const Schema sparseIndices{
        {uintProp("bufferView", true), uintProp("byteOffset"), uintProp("componentType", true)}};
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
    static const Schema skin{
        {uintProp("inverseBindMatrices"), uintProp("skeleton"), uintArrayProp("joints", true, true)}};
    static const Schema perspective{
        {numberProp("aspectRatio"), numberProp("yfov", true), numberProp("zfar"), numberProp("znear", true)}};
    static const Schema orthographic{
        {numberProp("xmag", true), numberProp("ymag", true), numberProp("zfar", true), numberProp("znear", true)}};
    static const Schema camera{
        {stringProp("type", true), objectProp("perspective", perspective), objectProp("orthographic", orthographic)}};
    static const Schema channelTarget{{uintProp("node"), stringProp("path", true)}};
    static const Schema channel{{uintProp("sampler", true), objectProp("target", channelTarget, true)}};
    static const Schema animationSampler{
        {uintProp("input", true), stringProp("interpolation"), uintProp("output", true)}};
    static const Schema animation{
        {objectArrayProp("channels", channel, true), objectArrayProp("samplers", animationSampler, true)}};
    static const Schema asset{
        {stringProp("version", true), stringProp("generator"), stringProp("minVersion"), stringProp("copyright")}};
    static const Schema spot{{numberProp("innerConeAngle"), numberProp("outerConeAngle")}};
    static const Schema light{{stringProp("type", true), numberArrayProp("color", 3), numberProp("intensity"),
                               numberProp("range"), objectProp("spot", spot)}};
    static const Schema lightsExt{{objectArrayProp("lights", light, true)}};
    static const Schema root{
        {objectProp("asset", asset, true), uintProp("scene"), objectArrayProp("scenes", scene),
         objectArrayProp("nodes", node), objectArrayProp("meshes", mesh), objectArrayProp("accessors", accessor),
         objectArrayProp("bufferViews", bufferView), objectArrayProp("buffers", buffer),
         objectArrayProp("images", image), objectArrayProp("textures", texture), objectArrayProp("samplers", sampler),
         objectArrayProp("materials", material), objectArrayProp("skins", skin), objectArrayProp("cameras", camera),
         objectArrayProp("animations", animation), stringArrayProp("extensionsUsed"),
         stringArrayProp("extensionsRequired")},
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
    if (declared != fileSize) fail(cat("GLB header declares ", declared, " bytes but the file has ", fileSize));
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
    static const std::array<std::string_view, 8> kSupported = {"KHR_lights_punctual",
                                                               "KHR_materials_transmission",
                                                               "KHR_materials_ior",
                                                               "KHR_materials_volume",
                                                               "KHR_materials_emissive_strength",
                                                               "KHR_draco_mesh_compression",
                                                               "EXT_meshopt_compression",
                                                               "KHR_mesh_quantization"};
    return std::find(kSupported.begin(), kSupported.end(), name) != kSupported.end();
}

// Deepest nesting of objects/arrays, by a linear scan that skips strings.
// (nlohmann's callback parser would do this too, but quadratically on big arrays.)
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
            if (ext == prim.end() || !ext->contains("KHR_draco_mesh_compression") || !prim.contains("indices"))
                continue;
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
    // The distinct compressed ranges: views sharing one decode it again, and
    // must not multiply what the file's placeholders may allocate.
    std::set<std::tuple<std::uint64_t, std::uint64_t, std::uint64_t>> sources;
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
        if (placeholder[v.sourceBuffer])
            fail(cat(where, ".buffer ", v.sourceBuffer, " is a fallback buffer without data"));
        const std::uint64_t sourceBytes = jsonUInt(buffers[v.sourceBuffer], "byteLength", 0);
        if (v.sourceOffset > sourceBytes || v.sourceLength > sourceBytes - v.sourceOffset)
            fail(cat(where, " (byteOffset ", v.sourceOffset, " + byteLength ", v.sourceLength, ") exceeds buffers[",
                     v.sourceBuffer, "] (", sourceBytes, " bytes)"));
        if (v.stride == 0 || v.count == 0) fail(cat(where, ": byteStride and count must be at least 1"));
        const std::uint64_t viewOffset = jsonUInt(views[i], "byteOffset", 0),
                            viewBytes = jsonUInt(views[i], "byteLength", 0);
        if (v.count > viewBytes / v.stride)
            fail(cat(where, ": ", v.count, " elements of ", v.stride, " bytes exceed the bufferView's ", viewBytes,
                     " bytes"));
        if (viewBytes > maxMeshoptDecodedBytes(v.sourceLength))
            fail(cat(where, ": ", v.sourceLength, " compressed bytes cannot fill the bufferView's ", viewBytes,
                     " bytes"));
        covered[target] = std::max(covered[target], viewOffset + viewBytes);
        decodable[target] += maxMeshoptDecodedBytes(v.sourceLength);
        sources.emplace(v.sourceBuffer, v.sourceOffset, v.sourceLength);
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
    std::uint64_t allDecodable = 0, allCovered = 0;
    for (const auto& [buffer, offset, length] : sources) allDecodable += maxMeshoptDecodedBytes(length);
    for (std::size_t i = 0; i < buffers.size(); ++i) allCovered += placeholder[i] ? covered[i] : 0;
    if (allCovered > allDecodable)
        fail(cat("the EXT_meshopt_compression fallback buffers cover ", allCovered, " bytes, more than the file's ",
                 sources.size(), " distinct compressed ranges can decode to (", allDecodable, ")"));
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

}  // namespace

Prechecked precheckJson(const std::filesystem::path& path, bool binary, const Fail& fail) {
    const std::string text = readJsonText(path, binary, fail);
    // Before parsing: tinygltf converts extras/extensions recursively.
    if (jsonNestingDepth(text) > kMaxJsonNesting) fail(cat("JSON nested deeper than ", kMaxJsonNesting, " levels"));
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

}  // namespace rtlab::ecs::load::gltf
