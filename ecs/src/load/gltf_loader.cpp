// glTF 2.0 loader (.gltf / .glb) on top of tinygltf: loadGltf, which runs the
// stages below, and stage 2. tinygltf is a shared library here:
// TINYGLTF_IMPLEMENTATION must not be defined in any of the loader's files.
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
//
// Where each stage lives (shared declarations in gltf_internal.hpp):
//   1. gltf_precheck.cpp;
//   2. this file: the tinygltf parse, then the fix-ups the pre-check
//      prepared (hidden Draco indices restored, meshopt bufferViews decoded);
//   3. gltf_convert.cpp (driver, hierarchy, nodes, skins, cameras, lights),
//      gltf_meshes.cpp, gltf_accessors.cpp (incl. Draco-decoded attributes),
//      gltf_materials.cpp, gltf_animations.cpp;
//   4. gltf_commit.cpp.
#include "gltf_internal.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <optional>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

namespace rtlab::ecs::load {
namespace gltf {
namespace {

std::string lowercase(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    return s;
}

}  // namespace

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

namespace {

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
        const std::string problem = compression::decodeMeshopt(
            target.data() + view.byteOffset, source.data() + v.sourceOffset, static_cast<std::size_t>(v.sourceLength),
            static_cast<std::size_t>(v.count), static_cast<std::size_t>(v.stride), v.mode, v.filter);
        if (!problem.empty()) fail(cat("bufferViews[", v.view, "]: EXT_meshopt_compression: ", problem));
    }
}

// Images decoded for tinygltf (its image loader): as RGBA8 through
// decodeTexture, within kMaxTexturePixels each and the load's DecodeBudget in all.
bool decodeImage(tg::Image* image, const int index, std::string* err, std::string*, int, int,
                 const unsigned char* bytes, int size, void* user) {
    auto& budget = *static_cast<DecodeBudget*>(user);
    std::optional<Texture> t;
    try {
        t = decodeTexture(bytes, size < 0 ? 0 : std::size_t(size), cat("images[", index, "]"), budget);
    } catch (const InputError& e) {
        if (err) *err += std::string(e.what()) + "\n";
        return false;
    }
    if (!t) {
        if (err) *err += cat("images[", index, "]: not an image stb_image decodes\n");
        return false;
    }
    image->width = t->width;
    image->height = t->height;
    image->component = 4;
    image->bits = 8;
    image->pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    image->image = std::move(t->rgba8);
    return true;
}

// External files (buffers, images): regular files of at most
// kMaxSideFileBytes only (a uri naming /dev/zero or a pipe would read forever).
bool readSideFile(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
    std::optional<std::vector<unsigned char>> bytes = readRegularFile(path);
    if (!bytes) {
        if (err) *err += "cannot read '" + path + "' (missing, not a regular file, or over 2 GiB)\n";
        return false;
    }
    *out = std::move(*bytes);
    return true;
}

}  // namespace
}  // namespace gltf

std::vector<Entity> loadGltf(World& world, const std::filesystem::path& path, Entity parent,
                             DecodeBudget* sharedBudget) {
    using namespace gltf;
    DecodeBudget ownBudget;
    DecodeBudget& budget = sharedBudget ? *sharedBudget : ownBudget;
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
        loader.SetImageLoader(decodeImage, &budget);
        loader.SetFsCallbacks(
            tg::FsCallbacks{&tg::FileExists, &tg::ExpandFilePath, &readSideFile, &tg::WriteWholeFile, nullptr});
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
    Staged staged = GltfConverter(model, fail, budget, pre.placeholders).convert();
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
