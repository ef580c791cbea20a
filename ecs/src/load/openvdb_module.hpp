#pragma once
// The boundary between VolumeGrid (vdb_volume.cpp, in the ecs library) and
// rtlab's OpenVDB module (ecs/openvdb_module/openvdb_grid.cpp, built as
// librtlab_openvdb.so). VolumeGrid opens the module with dlopen the first
// time a volume is made or read: linking OpenVDB into every program cost each
// process start ~65 ms of relocations (docs/reliability.md), paid by every
// rtlab command, every reader-check process and every test.
#include <rtlab/core/math.hpp>
#include <rtlab/ecs/volume_grid.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

namespace rtlab::ecs {

// A grid's data; the module's subclass holds the OpenVDB tree.
struct VolumeGrid::Impl {
    virtual ~Impl() = default;
    // The trilinear density at a world-space point inside `bounds`.
    virtual float sampleInside(const vec3& worldPosition) const = 0;

    std::string name;
    Aabb bounds;  // world space; empty when every value is 0
    float maxDensity = 0.f;
    std::size_t activeVoxels = 0;
};

namespace openvdb_module {

// A module of another build is refused rather than called: the first two
// fields of Functions never move; abiToken (RTLAB_OPENVDB_ABI_TOKEN, which
// ecs/CMakeLists.txt derives from the compiler and the headers of this
// boundary) must match too.
inline constexpr std::uint32_t kAbiVersion = 1;

// What the module gives: `extern "C" const Functions* rtlab_openvdb_module()`.
// Both functions throw InputError (naming the file) on bad input, as
// VolumeGrid's do; the two sides are built together with one compiler.
struct Functions {
    std::uint32_t abiVersion;
    std::size_t implSize;  // sizeof(VolumeGrid::Impl) where the module was built
    const char* abiToken;  // RTLAB_OPENVDB_ABI_TOKEN where the module was built
    // The grid of VolumeGrid::makeProceduralFog, whose arguments are checked:
    // n lattice points per axis.
    std::unique_ptr<VolumeGrid::Impl> (*makeProceduralFog)(const Aabb& bounds, float voxelSize, float peakDensity,
                                                           std::uint32_t seed, const std::array<std::int32_t, 3>& n);
    // VolumeGrid::loadVdbInThisProcess past its checks that the file exists.
    std::unique_ptr<VolumeGrid::Impl> (*loadVdb)(const std::filesystem::path& path, const std::string& gridName);
};

inline constexpr const char* kEntryPoint = "rtlab_openvdb_module";

}  // namespace openvdb_module
}  // namespace rtlab::ecs
