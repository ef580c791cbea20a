#pragma once
// Decoders for compressed glTF geometry, kept out of the loader's other files
// (gltf_loader.cpp, gltf_*.cpp) so that the Draco headers (template-heavy) are
// compiled in exactly one translation unit (gltf_compression.cpp). Internal to
// the ecs module.
//
// Both decoders validate their parameters before calling the libraries
// (Debian's builds keep the libraries' assertions) and report malformed
// input as an error string; they never throw for bad data.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace rtlab::ecs::load::compression {

// ---- KHR_draco_mesh_compression ------------------------------------------

// One attribute to extract: the Draco attribute's unique id (the value in the
// extension's `attributes` object) and the layout of the glTF accessor it
// replaces (glTF component type, components per element).
struct DracoAttributeRequest {
    std::uint32_t dracoId = 0;
    int componentType = 0;  // 5120 .. 5126 (glTF / GL enums)
    int components = 0;     // 1 .. 16
};

struct DracoMesh {
    std::string error;  // non-empty: malformed data, nothing else is valid
    std::size_t points = 0;
    std::vector<std::uint32_t> indices;  // 3 per triangle, all < points
    // Per request, `points` elements converted to the requested component
    // type, tightly packed (little-endian, as glTF buffers are).
    std::vector<std::vector<unsigned char>> attributes;
};

// `maxPoints`: the most points the data may declare (its accessors' counts),
// checked before Draco allocates them.
DracoMesh decodeDracoMesh(const unsigned char* data, std::size_t size,
                          const std::vector<DracoAttributeRequest>& requests, std::size_t maxPoints);

// ---- EXT_meshopt_compression ---------------------------------------------

enum class MeshoptMode : std::uint8_t { Attributes, Triangles, Indices };
enum class MeshoptFilter : std::uint8_t { None, Octahedral, Quaternion, Exponential };

// Decodes `count` elements of `stride` bytes from `src` into `dst` (which
// holds count * stride bytes). Returns "" on success, else the problem.
std::string decodeMeshopt(unsigned char* dst, const unsigned char* src, std::size_t srcSize, std::size_t count,
                          std::size_t stride, MeshoptMode mode, MeshoptFilter filter);

}  // namespace rtlab::ecs::load::compression
