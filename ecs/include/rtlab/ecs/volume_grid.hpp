#pragma once
// A density grid for participating media. OpenVDB stays behind this opaque
// type: it is included by exactly one translation unit
// (ecs/openvdb_module/openvdb_grid.cpp), because its headers are slow to
// compile, and lives in a module (librtlab_openvdb.so) opened the first time
// a grid is made or read, because its library is slow to load.
#include <rtlab/core/math.hpp>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

namespace rtlab::ecs {

class VolumeGrid {
public:
    ~VolumeGrid();
    VolumeGrid(const VolumeGrid&) = delete;
    VolumeGrid& operator=(const VolumeGrid&) = delete;

    // Procedural fog: a soft noisy blob of density filling `bounds`
    // (peak density `peakDensity`), `voxelSize` world units per voxel.
    static std::shared_ptr<VolumeGrid> makeProceduralFog(const Aabb& bounds, float voxelSize, float peakDensity,
                                                         std::uint32_t seed);
    // The most voxels a procedural fog may have, one or all of a scene's
    // together (filling 2^25 takes seconds; a line of a scene file asks for it).
    static constexpr std::uint64_t kMaxProceduralVoxels = std::uint64_t{1} << 25;
    // The voxels makeProceduralFog fills for these bounds, or
    // kMaxProceduralVoxels + 1 when there would be more; 0 for bounds or a
    // voxel size it refuses.
    static std::uint64_t proceduralFogVoxels(const Aabb& bounds, float voxelSize);
    // Loads the float grid `gridName` ("" = the first float grid) of a .vdb
    // file. Throws InputError naming the file on any problem, and
    // std::runtime_error when the OpenVDB module is not installed.
    // OpenVDB crashes on some corrupt files: where a check command is set
    // (load::setReaderCheckCommand; rtlab sets one) the file is read in a
    // separate process first, and a crash there is an InputError here.
    static std::shared_ptr<VolumeGrid> loadVdb(const std::filesystem::path& path, const std::string& gridName = "");
    // The same without the separate process (what that process runs).
    static std::shared_ptr<VolumeGrid> loadVdbInThisProcess(const std::filesystem::path& path,
                                                            const std::string& gridName = "");

    const std::string& name() const;
    Aabb worldBounds() const;  // bounds of the active voxels, world space
    float maxDensity() const;  // majorant for delta tracking
    std::size_t activeVoxelCount() const;
    // Trilinearly interpolated density at a world-space position (0 outside).
    float density(const vec3& worldPosition) const;

    struct Impl;  // defined by the OpenVDB module's boundary (ecs/src/load/openvdb_module.hpp)

private:
    explicit VolumeGrid(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace rtlab::ecs
