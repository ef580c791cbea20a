#pragma once
// `rtlab export` (docs/scene-format.md, "Export"): any scene's triangles, in
// world space at its first frame, for other tools (Arches, pbrt, Blender) to
// run the very same workloads. Every mesh instance is written out (instancing
// is flattened); procedural geometry is left out and counted.
#include <rtlab/ecs/world.hpp>

#include <cstddef>
#include <filesystem>

namespace rtlab::ecs::save {

struct ExportStats {
    std::size_t triangles = 0;
    std::size_t vertices = 0;
    std::size_t materials = 0;
    std::size_t proceduralGeometriesLeftOut = 0;
};

// FILE.obj with its material library FILE.mtl beside it (Kd, d, Ns, Ke, Ni: the
// inverse of the OBJ loader's mapping; textures are not written). Each file is
// written under a temporary name and renamed.
ExportStats writeObj(const World& world, const std::filesystem::path& objPath);

// Binary little-endian PLY: vertices (x y z nx ny nz, float) and faces
// (vertex_indices, plus the material index of each face).
ExportStats writePly(const World& world, const std::filesystem::path& plyPath);

}  // namespace rtlab::ecs::save
