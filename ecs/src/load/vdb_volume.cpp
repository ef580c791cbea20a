// VolumeGrid: argument checks, the separate-process reader check, and the
// loading of rtlab's OpenVDB module (openvdb_module.hpp), which does the
// OpenVDB work. The module is looked for, in order, at
//   1. $RTLAB_OPENVDB_MODULE, when set (then nowhere else);
//   2. beside the running program as installed: BINDIR/../LIBDIR/rtlab/;
//   3. where this build tree put it;
//   4. where `cmake --install` puts it for the configured prefix.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/volume_grid.hpp>

#include "openvdb_module.hpp"
#include "reader_check.hpp"

#include <dlfcn.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <vector>

#ifndef RTLAB_OPENVDB_MODULE_FROM_BINDIR
#error "the ecs library's CMakeLists.txt defines where the OpenVDB module lies"
#endif

namespace rtlab::ecs {

namespace {

std::vector<std::filesystem::path> moduleCandidates() {
    std::error_code ec;
    if (const char* chosen = std::getenv("RTLAB_OPENVDB_MODULE"); chosen && *chosen) {
        const std::filesystem::path absolute = std::filesystem::absolute(chosen, ec);  // dlopen would search
        return {ec ? std::filesystem::path(chosen) : absolute};
    }
    std::vector<std::filesystem::path> candidates;
    const std::filesystem::path program = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (!ec) candidates.push_back((program.parent_path() / RTLAB_OPENVDB_MODULE_FROM_BINDIR).lexically_normal());
    candidates.emplace_back(RTLAB_OPENVDB_MODULE_BUILT);
    candidates.emplace_back(RTLAB_OPENVDB_MODULE_INSTALLED);
    return candidates;
}

// The module's functions, opened on first use and kept for the process's
// life. Not finding it is an installation fault (exit 1), not bad input.
const openvdb_module::Functions& openVdbModule() {
    static std::mutex mutex;
    static const openvdb_module::Functions* functions = nullptr;
    const std::lock_guard lock(mutex);
    if (functions) return *functions;
    std::string tried;
    for (const std::filesystem::path& candidate : moduleCandidates()) {
        tried += (tried.empty() ? "" : "; ") + candidate.string();
        std::error_code ec;
        if (!std::filesystem::exists(candidate, ec)) {
            tried += " (absent)";
            continue;
        }
        void* handle = dlopen(candidate.c_str(), RTLD_NOW | RTLD_LOCAL);
        if (!handle) {
            const char* why = dlerror();
            tried += std::string(" (") + (why ? why : "dlopen failed") + ")";
            continue;
        }
        using Entry = const openvdb_module::Functions* (*)();
        const auto entry = reinterpret_cast<Entry>(dlsym(handle, openvdb_module::kEntryPoint));
        const openvdb_module::Functions* found = entry ? entry() : nullptr;
        if (!found || found->abiVersion != openvdb_module::kAbiVersion || found->implSize != sizeof(VolumeGrid::Impl) ||
            std::strcmp(found->abiToken, RTLAB_OPENVDB_ABI_TOKEN) != 0) {
            tried += " (another build's module)";
            dlclose(handle);
            continue;
        }
        functions = found;  // never closed: grids made by it live until exit
        return *functions;
    }
    throw std::runtime_error(
        "volumes need rtlab's OpenVDB module librtlab_openvdb.so, which was not found or could not be loaded (tried " +
        tried + "); set RTLAB_OPENVDB_MODULE to its path");
}

}  // namespace

VolumeGrid::VolumeGrid(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
VolumeGrid::~VolumeGrid() = default;

namespace {

// What is wrong with a procedural fog's box and voxel size, or nullptr.
const char* fogLatticeProblem(const Aabb& bounds, float voxelSize) {
    if (!isFinite(bounds.lo) || !isFinite(bounds.hi) || !(bounds.lo.x < bounds.hi.x) || !(bounds.lo.y < bounds.hi.y) ||
        !(bounds.lo.z < bounds.hi.z))
        return "procedural fog: bounds must be finite with lo < hi on every axis";
    if (!std::isfinite(voxelSize) || !(voxelSize > 0.f)) return "procedural fog: voxel size must be finite and > 0";
    return nullptr;
}

}  // namespace

std::uint64_t VolumeGrid::proceduralFogVoxels(const Aabb& bounds, float voxelSize) {
    if (fogLatticeProblem(bounds, voxelSize)) return 0;  // makeProceduralFog says what is wrong
    const vec3 extent = bounds.extent();
    std::uint64_t total = 1;
    for (int a = 0; a < 3; ++a) {
        const double cells = std::floor(static_cast<double>(extent[a]) / static_cast<double>(voxelSize));
        if (!(cells < static_cast<double>(kMaxProceduralVoxels))) return kMaxProceduralVoxels + 1;  // NaN too
        total *= static_cast<std::uint64_t>(cells) + 1;
        if (total > kMaxProceduralVoxels) return kMaxProceduralVoxels + 1;
    }
    return total;
}

std::shared_ptr<VolumeGrid> VolumeGrid::makeProceduralFog(const Aabb& bounds, float voxelSize, float peakDensity,
                                                          std::uint32_t seed) {
    if (const char* problem = fogLatticeProblem(bounds, voxelSize)) throw std::invalid_argument(problem);
    if (!std::isfinite(peakDensity) || peakDensity < 0.f)
        throw std::invalid_argument("procedural fog: peak density must be finite and >= 0");
    if (proceduralFogVoxels(bounds, voxelSize) > kMaxProceduralVoxels)
        throw std::invalid_argument("procedural fog: bounds / voxel size need more than " +
                                    std::to_string(kMaxProceduralVoxels) + " voxels");

    // Lattice points i * voxelSize + bounds.lo, i = 0 .. n-1, all inside the box.
    const vec3 extent = bounds.extent();
    std::array<std::int32_t, 3> n{};
    for (int a = 0; a < 3; ++a)
        n[static_cast<std::size_t>(a)] =
            static_cast<std::int32_t>(std::floor(static_cast<double>(extent[a]) / static_cast<double>(voxelSize))) + 1;
    return std::shared_ptr<VolumeGrid>(
        new VolumeGrid(openVdbModule().makeProceduralFog(bounds, voxelSize, peakDensity, seed, n)));
}

std::shared_ptr<VolumeGrid> VolumeGrid::loadVdb(const std::filesystem::path& path, const std::string& gridName) {
    const std::string where = path.string();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw InputError(where, "cannot open: no such file");
    if (!std::filesystem::is_regular_file(path, ec)) throw InputError(where, "cannot open: not a regular file");
    // OpenVDB crashes on some corrupt blocks and leaks the trees of failed
    // reads: the file is read in a separate process first (reader_check.hpp).
    load::checkInSeparateProcess("vdb", "OpenVDB", path, gridName, where);
    return loadVdbInThisProcess(path, gridName);
}

std::shared_ptr<VolumeGrid> VolumeGrid::loadVdbInThisProcess(const std::filesystem::path& path,
                                                             const std::string& gridName) {
    const std::string where = path.string();
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw InputError(where, "cannot open: no such file");
    if (!std::filesystem::is_regular_file(path, ec)) throw InputError(where, "cannot open: not a regular file");
    return std::shared_ptr<VolumeGrid>(new VolumeGrid(openVdbModule().loadVdb(path, gridName)));
}

namespace load {
void readVdbForCheck(const std::filesystem::path& path, const std::string& gridName) {
    VolumeGrid::loadVdbInThisProcess(path, gridName);
}
}  // namespace load

const std::string& VolumeGrid::name() const { return impl_->name; }
Aabb VolumeGrid::worldBounds() const { return impl_->bounds; }
float VolumeGrid::maxDensity() const { return impl_->maxDensity; }
std::size_t VolumeGrid::activeVoxelCount() const { return impl_->activeVoxels; }

float VolumeGrid::density(const vec3& p) const {
    const Aabb& b = impl_->bounds;
    // Written so that NaN coordinates fail the test and return 0.
    if (!(p.x >= b.lo.x && p.x <= b.hi.x && p.y >= b.lo.y && p.y <= b.hi.y && p.z >= b.lo.z && p.z <= b.hi.z))
        return 0.f;
    return impl_->sampleInside(p);
}

}  // namespace rtlab::ecs
