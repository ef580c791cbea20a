#pragma once
// Scene sources (DESIGN.md): "builtin:NAME", a .gltf/.glb, .obj, .ply or .fbx
// file, or a scene .json that references glTF and VDB files. Every loader throws
// rtlab::InputError naming the file and the problem on bad input; it never
// crashes, hangs or leaves a half-built World behind a successful return.
#include <rtlab/ecs/world.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace rtlab::ecs::load {

// Dispatches on the source string. Adds a default camera and light when the
// source has none, so every scene renders.
void loadScene(World& world, const std::string& source);

// What one scene load may decode (docs/reliability.md, "Limits"), across
// every file it reads: a scene .json's glTF entries share one. A small file
// can declare gigabytes (a solid image of 8192 x 8192 pixels is a few KB; an
// accessor read by many primitives; one texture named by many materials);
// real files decode to a bounded multiple of their bytes.
struct DecodeBudget {
    // Texture pixels: 2^28 (1 GiB as RGBA8), plus 16 per byte of compressed
    // image read (64 bytes of RGBA8, the geometry's ratio: photographs and
    // JPEG maps compress far less, a solid PNG over a thousand times more).
    static constexpr std::uint64_t kBasePixels = std::uint64_t(1) << 28;
    static constexpr std::uint64_t kPixelsPerImageByte = 16;
    // glTF geometry (every accessor read, as 4-byte components, and every
    // deformable instance's copy): 1 GiB, plus 64 per byte of the glTF buffers read.
    static constexpr std::uint64_t kBaseGeometryBytes = std::uint64_t(1) << 30;
    static constexpr std::uint64_t kGeometryBytesPerBufferByte = 64;

    std::uint64_t pixels = 0, imageBytes = 0;
    std::uint64_t geometryBytes = 0, bufferBytes = 0;

    std::uint64_t pixelLimit() const { return kBasePixels + kPixelsPerImageByte * imageBytes; }
    std::uint64_t geometryLimit() const { return kBaseGeometryBytes + kGeometryBytesPerBufferByte * bufferBytes; }
};

// glTF 2.0 (.gltf or .glb) through tinygltf: node hierarchy, triangle meshes
// (strips/fans converted; points/lines rejected), all index widths, normals
// (generated when missing), UV0, materials, cameras, KHR_lights_punctual,
// animations, skins, morph targets. New root entities are parented to
// `parent` when it is valid. Returns the entities created for the glTF scene's
// root nodes. `budget`: shared with the other files of one scene load (a
// scene .json's entries); the file's own when null.
std::vector<Entity> loadGltf(World& world, const std::filesystem::path& path, Entity parent = kNullEntity,
                             DecodeBudget* budget = nullptr);

// Wavefront OBJ + MTL through tinyobjloader (docs/scene-format.md, "OBJ and
// MTL"): one entity and mesh per object or group, a geometry per material,
// polygons triangulated (concave ones by ear clipping), normals computed where
// missing; a missing .mtl or texture is a warning in world.loadReport().
// Returns the entities created (parented to `parent` when it is valid).
std::vector<Entity> loadObj(World& world, const std::filesystem::path& path, Entity parent = kNullEntity);

// PLY and FBX through assimp (docs/scene-format.md, "PLY and FBX"): the node
// tree as entities, triangle meshes (points and lines skipped with a
// warning), normals computed where missing, UV0, materials and their diffuse
// textures. Returns the root entities (parented to `parent` when it is valid).
std::vector<Entity> loadWithAssimp(World& world, const std::filesystem::path& path, Entity parent = kNullEntity);
// Files read by libraries that crash or hang on some corrupt input (assimp:
// PLY, FBX; OpenVDB: .vdb) are first read by a separate process, a crash or a
// hang there being an InputError here (docs/reliability.md): COMMAND... KIND
// PARENT_PID FILE [ARGUMENT] must read FILE as the loader would and exit 0,
// or 2 with one line "rtlab: FILE: problem" on stderr when it is bad
// (runReaderCheck does exactly this). rtlab sets {"/proc/self/exe",
// "__check-file"}; empty (the default for other programs): no check.
void setReaderCheckCommand(std::vector<std::string> command);
// The check itself, in the checking process: KIND "assimp" or "vdb"
// (ARGUMENT: the grid name); returns its exit code (3: not asked by PARENT_PID).
int runReaderCheck(const std::string& kind, const std::string& parentPid, const std::filesystem::path& path,
                   const std::string& argument);

// Scene description JSON (docs/scene-format.md).
void loadSceneJson(World& world, const std::filesystem::path& path);

// Built-in scenes: "showcase" (default; exercises every effect), "cornell",
// and the scalable "terrain?triangles=N", "forest?instances=M",
// "hairball?triangles=N" (curly strands) and "slivers?triangles=N" (the BVH
// worst case) (each also takes "seed"). `nameAndParameters` is the
// source after "builtin:", "NAME" or "NAME?key=value&key=value"; unknown names
// or parameters and bad or out-of-range values throw InputError. The
// parameters used are recorded in world.settings().parameters.
void loadBuiltinScene(World& world, const std::string& nameAndParameters);
std::vector<std::string> builtinSceneNames();
// The checks of loadBuiltinScene without building anything: throws the same
// InputError for an unknown name or a bad parameter.
void checkBuiltinScene(const std::string& nameAndParameters);

// Adds a camera looking at the scene bounds from +Z when the world has no
// active camera, and a directional light when it has no light at all.
void addDefaultCameraAndLight(World& world);

// Helpers shared by the file loaders (glTF, OBJ, assimp).
// A node matrix (affine, finite) as translation, rotation and scale; a
// singular one keeps its translation and axis lengths (its rotation is lost).
LocalTransform localTransformOf(const mat4& matrix);
// Adds staged textures and materials to the world (a material's
// baseColorTexture indexes `textures`), and a loader's skipped primitives and
// warnings to its load report; returns the world's id of each material.
std::vector<MaterialId> commitMaterials(World& world, std::vector<Texture>&& textures,
                                        std::vector<Material>&& materials, std::uint32_t skippedLines,
                                        std::uint32_t skippedPoints, const std::vector<std::string>& warnings);

// The most pixels one texture may have (2^26, e.g. 8192 x 8192: 256 MB as
// RGBA8): a small compressed image can declare gigapixels.
inline constexpr std::uint64_t kMaxTexturePixels = std::uint64_t(1) << 26;
// The largest file a loader reads whole beside the scene file (textures,
// external glTF buffers): 2 GiB.
inline constexpr std::uint64_t kMaxSideFileBytes = std::uint64_t(2) << 30;

// Compressed image bytes (anything stb_image reads) as an 8-bit RGBA texture;
// nothing when they do not decode. InputError naming `name` when the image
// declares more than kMaxTexturePixels, or takes `budget` past its pixel
// limit, checked from the header before decoding.
std::optional<Texture> decodeTexture(const unsigned char* bytes, std::size_t size, const std::string& name,
                                     DecodeBudget& budget);
// A file read whole, when it is a regular file of at most maxBytes; nothing
// otherwise (missing, a directory, a device such as /dev/zero, a pipe, too big).
std::optional<std::vector<unsigned char>> readRegularFile(const std::filesystem::path& path,
                                                          std::uint64_t maxBytes = kMaxSideFileBytes);
// The texture a scene file names: `written` as in the file, relative to `dir`
// (Windows separators accepted); when that is not there, its file name in
// `dir` (an absolute path of the author's machine). Nothing when not found or
// unreadable.
std::optional<Texture> readTextureNamed(const std::filesystem::path& dir, std::string written, DecodeBudget& budget);
// Whether some texel is not fully opaque (the texture cuts out: an alpha mask).
bool hasTransparentTexel(const Texture& texture);
// A Phong / MTL shininess exponent as roughness: sqrt(2 / (Ns + 2)), in [0, 1].
float roughnessFromPhongExponent(float exponent);

// Geometry helpers shared by the loaders and builtin scenes.
// Area-weighted vertex normals; degenerate ones become (0, 0, 1).
std::vector<vec3> generateVertexNormals(const std::vector<vec3>& positions, const std::vector<std::uint32_t>& indices);
// World-space bounds of every mesh instance.
Aabb worldBounds(const World& world);
// Triangles of zero area (a repeated index, coincident or collinear
// vertices): loaded as they are, never hit by a ray. Draco's encoder drops
// them, so a Draco file has that many triangles fewer than its source.
std::size_t degenerateTriangleCount(const MeshAsset& mesh);

}  // namespace rtlab::ecs::load
