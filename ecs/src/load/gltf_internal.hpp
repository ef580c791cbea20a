#pragma once
// Declarations shared by the glTF loader's translation units (gltf_loader.cpp and the gltf_*.cpp files of
// its stages): limits, the error helper, what the pre-check hands on, the staging structures and the
// stage-3 converter class. Internal to the ecs module.
#include "gltf_compression.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <tiny_gltf.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace rtlab::ecs::load::gltf {

namespace tg = tinygltf;

// Limits that keep malformed input from exhausting the stack or memory.
constexpr std::uint64_t kMaxJsonInteger = 0x7fffffffu;          // tinygltf stores indices in int
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

// First non-blank line, trimmed, at most ~300 characters (tinygltf quotes
// whole data URIs in some messages).
std::string firstLineTrimmed(const std::string& text);

// ---- stage 1: structural pre-check (gltf_precheck.cpp) ---------------------

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

// Checks the file's JSON (and GLB container) before tinygltf sees it; throws
// through `fail` on malformed input.
Prechecked precheckJson(const std::filesystem::path& path, bool binary, const Fail& fail);

// ---- stage 3: validation and conversion into staging structures ------------

// One accepted (component type, normalized) combination; for float the
// normalized flag is ignored, for integers it must match when `anyNorm` is false.
struct Format {
    int componentType;
    bool normalized = false;
    bool anyNorm = false;
};

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
    std::vector<Material> materials;               // baseColorTexture: index into textures
    std::vector<MeshAsset> meshes;                 // Geometry::material: index into materials
    std::vector<StagedNode> nodes;                 // parents before children
    std::vector<int> roots;                        // indices into nodes
    std::vector<std::optional<StagedSkin>> skins;  // by glTF skin index
    std::vector<StagedClip> clips;
    std::vector<int> nodeSlot;                 // glTF node -> index into nodes, -1 if not loaded
    std::uint32_t skippedPointPrimitives = 0;  // in the converted meshes
    std::uint32_t skippedLinePrimitives = 0;   // lines, line loops and line strips
};

// Converted glTF mesh before per-instance variants are made.
struct BaseMesh {
    MeshAsset asset;  // all data: morph targets, joints/weights when present
    std::size_t targetCount = 0;
    bool skinnable = false;          // every primitive has JOINTS_0 and WEIGHTS_0
    std::uint32_t jointsNeeded = 0;  // 1 + largest joint index with non-zero weight
    int rigidVariant = -1;           // index into Staged::meshes, shared by rigid instances
};

// Components of an accessor type (SCALAR 1 ... MAT4 16); 0 for an unknown type.
int componentCount(int type);

// Validates the parsed model and converts what the loaded scene reaches. The
// members are defined by concept: gltf_convert.cpp (driver, hierarchy, nodes,
// skins, cameras, lights), gltf_meshes.cpp, gltf_accessors.cpp,
// gltf_materials.cpp and gltf_animations.cpp.
class GltfConverter {
public:
    // Charges what it decodes to `budget` (the glTF geometry part of a
    // DecodeBudget), whose allowance grows by the model's buffers' bytes, but
    // for `placeholders` (Prechecked's): they hold decoded meshopt data, not
    // bytes of the file.
    GltfConverter(const tg::Model& model, const Fail& fail, DecodeBudget& budget,
                  const std::vector<std::pair<std::size_t, std::uint64_t>>& placeholders = {});

    Staged convert();

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

    // ---- hierarchy, nodes, skins, cameras and lights (gltf_convert.cpp) ------------
    void validateHierarchy();
    std::vector<int> sceneRoots() const;
    void traverse(const std::vector<int>& roots);
    StagedNode stageNode(int index, int parent);
    LocalTransform nodeTransform(int index) const;
    const StagedSkin& stageSkin(int index);
    Camera convertCamera(int index) const;
    Light convertLight(int index) const;

    // ---- meshes and mesh instances (gltf_meshes.cpp) ---------------------------------
    void checkDeclaredGeometry(const std::vector<int>& roots) const;
    void stageInstance(int nodeIndex, StagedNode& out);
    BaseMesh& baseMesh(int meshIndex);
    BaseMesh convertMesh(int meshIndex);
    Geometry convertPrimitive(const tg::Primitive& prim, const std::string& where, bool& hasSkinAttributes,
                              std::uint32_t& jointsNeeded);
    static int attribute(const tg::Primitive& prim, const char* name) {
        const auto it = prim.attributes.find(name);
        return it == prim.attributes.end() ? -1 : it->second;
    }
    static int attribute(const std::map<std::string, int>& attrs, const char* name) {
        const auto it = attrs.find(name);
        return it == attrs.end() ? -1 : it->second;
    }

    // ---- accessors (gltf_accessors.cpp) ----------------------------------------------
    std::vector<vec3> readVec3(int accessor, const std::string& what, std::size_t expectedCount,
                               const std::vector<Format>& formats, const char* expected);
    std::vector<vec3> readPositions(int accessor, const std::string& what);
    std::vector<vec3> readNormals(int accessor, const std::string& what, std::size_t n);
    std::vector<vec3> readPositionDeltas(int accessor, const std::string& what, std::size_t n);
    std::vector<std::uint32_t> readIndices(int accessor, const std::string& what, std::size_t n);
    std::optional<std::vector<std::uint32_t>> decodeDraco(const tg::Primitive& prim, const std::string& where);
    void requireCount(const AccessorView& v, const std::string& what, std::size_t expected) const;
    const unsigned char* bufferViewBytes(int index, std::size_t& length, const std::string& user) const;
    AccessorView view(int index, const std::string& what, std::initializer_list<int> types,
                      const std::vector<Format>& formats, const char* expected) const;
    template <class T, class Read>
    static std::vector<T> gather(const AccessorView& v, Read read);
    std::vector<float> readFloats(const AccessorView& v, const std::string& what) const;
    static std::vector<std::uint32_t> readUInts(const AccessorView& v);
    // Counts bytes against the budget's geometry limit, before they are allocated.
    void chargeDecoded(std::uint64_t bytes, const std::string& what) const;

    // ---- materials and textures (gltf_materials.cpp) ---------------------------------
    int defaultMaterial();
    int localMaterial(int index);
    float factor(double v, float lo, float hi, const std::string& what) const;
    std::optional<double> extensionNumber(const tg::Material& mat, const char* ext, const char* key,
                                          const std::string& label) const;
    Material convertMaterial(int index);
    std::uint32_t localTexture(int textureIndex);
    std::optional<Texture> convertImage(int index) const;

    // ---- animations (gltf_animations.cpp) --------------------------------------------
    void convertAnimations();
    AnimationChannel convertChannel(const tg::AnimationSampler& sampler, const tg::AnimationChannel& ch,
                                    const std::string& where) const;

    const tg::Model& m_;
    const Fail& fail_;
    DecodeBudget& budget_;
    Staged s_;
    std::vector<int> parentOf_;
    std::vector<int> materialSlot_;
    std::vector<int> imageSlot_;
    std::vector<std::optional<BaseMesh>> baseMeshes_;
    int defaultMaterial_ = -1;
    bool quantized_ = false;                             // the file uses KHR_mesh_quantization
    std::map<int, std::vector<unsigned char>> decoded_;  // Draco-decoded accessors of the current primitive
};

// ---- stage 4: commit (gltf_commit.cpp) --------------------------------------

// Adds the staged scene to the World (roots under `parent` when it is alive)
// and returns the root entities. Cannot fail on bad input.
std::vector<Entity> commit(World& world, Staged&& s, Entity parent);

}  // namespace rtlab::ecs::load::gltf
