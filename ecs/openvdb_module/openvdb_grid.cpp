// librtlab_openvdb.so: the one translation unit of the project that includes
// OpenVDB (DESIGN.md: its headers are slow to compile). It is a module that
// VolumeGrid (ecs/src/load/vdb_volume.cpp) opens with dlopen the first time a
// volume is made or read, so a run without volumes never loads OpenVDB's
// library, whose relocations cost ~65 ms of every process start
// (docs/reliability.md). The boundary is ecs/src/load/openvdb_module.hpp.
//
// Density conventions (both sources):
//   * a float grid, fog-volume style: background 0, values >= 0 and finite;
//   * density(p) is the trilinear (tools::BoxSampler) interpolation of the
//     voxel values at p's index-space position; it is exactly 0 outside
//     worldBounds(), which is the trilinear support of the non-zero values
//     (their index bounding box grown by one voxel on every side);
//   * maxDensity() is the largest value stored anywhere in the tree (active
//     or not), so it is a true majorant of density().
//
// Thread safety: a grid is immutable after construction. density() builds a
// non-registering ValueAccessor on the stack per call (no shared mutable
// cache), so any number of threads may sample one grid at once.
#include <rtlab/core/error.hpp>
#include <rtlab/core/rng.hpp>

#include "../src/load/openvdb_module.hpp"

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tree/ValueAccessor.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <mutex>
#include <new>
#include <sstream>
#include <stdexcept>

namespace rtlab::ecs {

namespace {

// A grid read or made here: the OpenVDB tree behind VolumeGrid's data.
struct OpenVdbGrid final : VolumeGrid::Impl {
    openvdb::FloatGrid::Ptr grid;

    float sampleInside(const vec3& p) const override {
        const openvdb::Vec3d indexPos = grid->transform().worldToIndex(openvdb::Vec3d(p.x, p.y, p.z));
        // Non-registering accessor on the stack: a private cache, no shared
        // state; valid because the tree never changes after construction.
        openvdb::tree::ValueAccessor<const openvdb::FloatTree, false> acc(grid->constTree());
        return openvdb::tools::BoxSampler::sample(acc, indexPos);
    }
};

void initializeOpenVdbOnce() {
    static std::once_flag flag;
    std::call_once(flag, [] { openvdb::initialize(); });
}

// ---- procedural fog ---------------------------------------------------------

// Deterministic lattice value in [0, 1) from integer coordinates and a seed.
float latticeValue(std::int32_t x, std::int32_t y, std::int32_t z, std::uint32_t seed) {
    std::uint32_t h = pcgHash(seed ^ 0x68e31da4u);
    h = pcgHash(h ^ static_cast<std::uint32_t>(x));
    h = pcgHash(h ^ static_cast<std::uint32_t>(y));
    h = pcgHash(h ^ static_cast<std::uint32_t>(z));
    return static_cast<float>(h >> 8) * (1.0f / 16777216.0f);
}

float quintic(float t) { return t * t * t * (t * (t * 6.f - 15.f) + 10.f); }

// Value noise in [0, 1): trilinear blend (quintic weights) of lattice values.
float valueNoise(float x, float y, float z, std::uint32_t seed) {
    const float fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
    const auto ix = static_cast<std::int32_t>(fx), iy = static_cast<std::int32_t>(fy),
               iz = static_cast<std::int32_t>(fz);
    const float ux = quintic(x - fx), uy = quintic(y - fy), uz = quintic(z - fz);
    float c[2][2][2];
    for (int k = 0; k < 2; ++k)
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i) c[k][j][i] = latticeValue(ix + i, iy + j, iz + k, seed);
    auto lerp = [](float a, float b, float t) { return a + (b - a) * t; };
    const float y0 = lerp(lerp(c[0][0][0], c[0][0][1], ux), lerp(c[0][1][0], c[0][1][1], ux), uy);
    const float y1 = lerp(lerp(c[1][0][0], c[1][0][1], ux), lerp(c[1][1][0], c[1][1][1], ux), uy);
    return lerp(y0, y1, uz);
}

// Three octaves of value noise over the unit cube, in [0, 1).
float fogNoise(float u, float v, float w, std::uint32_t seed) {
    float sum = 0.f, amplitude = 1.f, norm = 0.f, frequency = 3.f;
    for (std::uint32_t octave = 0; octave < 3; ++octave) {
        sum += amplitude * valueNoise(u * frequency, v * frequency, w * frequency, seed + 0x9e3779b9u * octave);
        norm += amplitude;
        amplitude *= 0.5f;
        frequency *= 2.f;
    }
    return sum / norm;
}

float smoothstep(float edge0, float edge1, float x) {
    const float t = std::clamp((x - edge0) / (edge1 - edge0), 0.f, 1.f);
    return t * t * (3.f - 2.f * t);
}

// Fog density at normalised box coordinates (u, v, w) in [0, 1]^3, as a
// fraction of the peak: a noisy ellipsoidal blob, 1 - smoothstep falloff from
// the centre. The noise moves the falloff edge by at most 0.15, so the
// density is exactly 0 where r >= 0.9: within 0.1 half-extents of every face.
float fogShape(float u, float v, float w, std::uint32_t seed) {
    const float dx = 2.f * u - 1.f, dy = 2.f * v - 1.f, dz = 2.f * w - 1.f;
    const float r = std::sqrt(dx * dx + dy * dy + dz * dz);  // 1 at the face centres
    if (r >= 0.9f) return 0.f;                               // the displaced distance is >= 0.75
    const float n = fogNoise(u, v, w, seed);
    const float displaced = r + 0.3f * (n - 0.5f);  // in [r - 0.15, r + 0.15)
    const float falloff = 1.f - smoothstep(0.35f, 0.75f, displaced);
    return std::clamp(falloff * (0.4f + 0.6f * n), 0.f, 1.f);
}

// ---- shared grid analysis ---------------------------------------------------

struct GridStats {
    bool allFinite = true;
    bool allNonNegative = true;
    float badValue = 0.f;
    openvdb::Coord badCoord;
    float maxValue = 0.f;
    openvdb::CoordBBox nonZeroIndexBounds;  // empty when every value is 0
};

// Visits every stored value (active or not, voxels and tiles) once.
GridStats analyse(const openvdb::FloatGrid& grid) {
    GridStats s;
    for (auto it = grid.tree().cbeginValueAll(); it; ++it) {
        const float v = *it;
        if (!std::isfinite(v) || v < 0.f) {
            if (s.allFinite && s.allNonNegative) {
                s.badValue = v;
                s.badCoord = it.getCoord();
            }
            if (!std::isfinite(v)) s.allFinite = false;
            else s.allNonNegative = false;
            continue;
        }
        s.maxValue = std::max(s.maxValue, v);
        if (v != 0.f) {
            openvdb::CoordBBox box;
            it.getBoundingBox(box);
            s.nonZeroIndexBounds.expand(box);
        }
    }
    return s;
}

// World bounds of the trilinear support of an index box: the box grown by one
// voxel on every side, its 8 corners mapped through the (affine) transform.
Aabb worldSupport(const openvdb::math::Transform& xform, const openvdb::CoordBBox& indexBox) {
    Aabb out;
    if (indexBox.empty()) return out;
    const openvdb::Vec3d lo = indexBox.min().asVec3d() - openvdb::Vec3d(1.0);
    const openvdb::Vec3d hi = indexBox.max().asVec3d() + openvdb::Vec3d(1.0);
    for (int i = 0; i < 8; ++i) {
        const openvdb::Vec3d corner{(i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(), (i & 4) ? hi.z() : lo.z()};
        const openvdb::Vec3d w = xform.indexToWorld(corner);
        out.extend(vec3(static_cast<float>(w.x()), static_cast<float>(w.y()), static_cast<float>(w.z())));
    }
    // Conservative by one float ulp-ish step so float rounding of the corners
    // never clips a sample whose (double) index position is inside.
    const vec3 pad = 1e-6f * glm::max(glm::abs(out.lo), glm::abs(out.hi)) + vec3(1e-12f);
    out.lo -= pad;
    out.hi += pad;
    return out;
}

std::string describeValue(float v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

std::string describeCoord(const openvdb::Coord& c) {
    std::ostringstream os;
    os << "(" << c.x() << ", " << c.y() << ", " << c.z() << ")";
    return os.str();
}

// OpenVDB messages look like "IoError: not a VDB file"; keep the text only.
std::string openVdbReason(const std::exception& e) {
    std::string msg = e.what();
    for (const char* prefix :
         {"IoError: ", "RuntimeError: ", "ValueError: ", "TypeError: ", "LookupError: ", "KeyError: ", "IndexError: ",
          "ArithmeticError: ", "NotImplementedError: ", "ReferenceError: "})
        if (msg.rfind(prefix, 0) == 0) return msg.substr(std::strlen(prefix));
    return msg;
}

// Walks the container layout of a seekable .vdb file (format >= 222, i.e.
// OpenVDB 3 and later, written by io::File): header, file metadata and the
// chain of grid descriptors with their byte offsets, never allocating more
// than a few bytes. Returns "" when every grid lies inside the file, else the
// problem. Catching truncation here matters: OpenVDB's tree readers are not
// exception-safe and leak the nodes read so far when a read fails midway.
// Older or stream-written files (no offsets) are left to OpenVDB.
std::string checkVdbLayout(std::istream& in, std::uint64_t fileSize) {
    in.clear();
    in.seekg(0);
    std::uint64_t pos = 0;
    const auto read = [&](void* dst, std::uint64_t n) {
        if (n > fileSize - pos) return false;
        in.read(static_cast<char*>(dst), static_cast<std::streamsize>(n));
        if (in.gcount() != static_cast<std::streamsize>(n)) return false;
        pos += n;
        return true;
    };
    const auto skip = [&](std::uint64_t n) {
        if (n > fileSize - pos) return false;
        pos += n;
        in.seekg(static_cast<std::streamoff>(pos));
        return static_cast<bool>(in);
    };
    const auto skipString = [&] {
        std::uint32_t length = 0;
        return read(&length, sizeof length) && skip(length);
    };
    const std::string truncatedHeader = "truncated or corrupt VDB file (the header ends early)";

    std::int64_t magic = 0;
    std::uint32_t version = 0;
    if (!read(&magic, sizeof magic) || !read(&version, sizeof version)) return truncatedHeader;
    if (version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION) return "";
    char hasGridOffsets = 0;
    // Library major + minor version, the offsets flag, the 36-character UUID.
    if (!skip(8) || !read(&hasGridOffsets, 1)) return truncatedHeader;
    if (!hasGridOffsets) return "";
    if (!skip(36)) return truncatedHeader;

    std::uint32_t metaCount = 0;
    if (!read(&metaCount, sizeof metaCount)) return truncatedHeader;
    for (std::uint32_t i = 0; i < metaCount; ++i) {
        std::uint32_t valueBytes = 0;
        // name, type name, value size, value
        if (!skipString() || !skipString() || !read(&valueBytes, sizeof valueBytes) || !skip(valueBytes))
            return "truncated or corrupt VDB file (the file metadata ends early)";
    }
    std::int32_t gridCount = 0;
    if (!read(&gridCount, sizeof gridCount) || gridCount < 0) return truncatedHeader;
    for (std::int32_t g = 0; g < gridCount; ++g) {
        const std::string which = "grid #" + std::to_string(g + 1) + " of " + std::to_string(gridCount);
        std::int64_t offsets[3] = {0, 0, 0};  // grid, blocks, end
        // unique name, type name, instance parent name, offsets
        if (!skipString() || !skipString() || !skipString() || !read(offsets, sizeof offsets))
            return "truncated or corrupt VDB file (the descriptor of " + which + " ends early)";
        if (offsets[0] < static_cast<std::int64_t>(pos) || offsets[1] < offsets[0] || offsets[2] < offsets[1])
            return "corrupt VDB file (inconsistent offsets in the descriptor of " + which + ")";
        if (static_cast<std::uint64_t>(offsets[2]) > fileSize)
            return "truncated VDB file (" + which + " ends at byte " + std::to_string(offsets[2]) + ", the file has " +
                   std::to_string(fileSize) + " bytes)";
        pos = static_cast<std::uint64_t>(offsets[2]);
        in.seekg(static_cast<std::streamoff>(pos));
        if (!in) return "truncated or corrupt VDB file";
    }
    return "";
}

// Fills the lattice points i * voxelSize + bounds.lo, i < n on each axis
// (the arguments are checked by VolumeGrid::makeProceduralFog).
std::unique_ptr<VolumeGrid::Impl> makeProceduralFog(const Aabb& bounds, float voxelSize, float peakDensity,
                                                    std::uint32_t seed, const std::array<std::int32_t, 3>& n) {
    const vec3 extent = bounds.extent();
    initializeOpenVdbOnce();
    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.f);
    openvdb::math::Transform::Ptr xform = openvdb::math::Transform::createLinearTransform(voxelSize);
    xform->postTranslate(openvdb::Vec3d(bounds.lo.x, bounds.lo.y, bounds.lo.z));
    grid->setTransform(xform);
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid->setName("procedural_fog");

    if (peakDensity > 0.f) {
        // Serial fill: every voxel is a pure function of (i, j, k, seed), the
        // order of insertion is fixed, so the tree is identical on every run.
        // Not registered with the tree: a registered accessor grows the
        // tree's accessor table, and prune() then walks it with TBB's
        // concurrent_hash_map iterator, which casts its bucket marker (3) to
        // a node pointer: UBSan stops there (fuzz_scene_json). Nothing else
        // touches the tree during the fill, so nothing needs the registration.
        openvdb::tree::ValueAccessor<openvdb::FloatTree, false> acc(grid->tree());
        for (std::int32_t k = 0; k < n[2]; ++k) {
            const float w = static_cast<float>(k) * voxelSize / extent.z;
            for (std::int32_t j = 0; j < n[1]; ++j) {
                const float v = static_cast<float>(j) * voxelSize / extent.y;
                for (std::int32_t i = 0; i < n[0]; ++i) {
                    const float u = static_cast<float>(i) * voxelSize / extent.x;
                    const float d = peakDensity * fogShape(u, v, w, seed);
                    if (d > 0.f) acc.setValue(openvdb::Coord(i, j, k), std::min(d, peakDensity));
                }
            }
        }
        grid->tree().prune();
    }

    auto impl = std::make_unique<OpenVdbGrid>();
    const GridStats stats = analyse(*grid);
    impl->bounds = worldSupport(grid->transform(), stats.nonZeroIndexBounds);
    impl->maxDensity = stats.maxValue;
    impl->activeVoxels = static_cast<std::size_t>(grid->activeVoxelCount());
    impl->name = grid->getName();
    impl->grid = std::move(grid);
    return impl;
}

// Reads a .vdb file that VolumeGrid::loadVdbInThisProcess found to exist.
std::unique_ptr<VolumeGrid::Impl> loadVdb(const std::filesystem::path& path, const std::string& gridName) {
    const std::string where = path.string();
    std::error_code ec;
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(where, "cannot open: " + std::string(std::strerror(errno)));
    {
        // OpenVDB files start with the 64-bit magic number 0x56444220 ("VDB ")
        // and the 32-bit file format version. Checking the version here keeps
        // OpenVDB from logging its own warning on stderr before it throws.
        std::int64_t magic = 0;
        in.read(reinterpret_cast<char*>(&magic), sizeof magic);
        if (in.gcount() != static_cast<std::streamsize>(sizeof magic) || magic != openvdb::OPENVDB_MAGIC)
            throw InputError(where, "not a VDB file (bad magic number)");
        std::uint32_t version = 0;
        in.read(reinterpret_cast<char*>(&version), sizeof version);
        if (in.gcount() != static_cast<std::streamsize>(sizeof version))
            throw InputError(where, "truncated or corrupt VDB file (unexpected end of data)");
        if (version > openvdb::OPENVDB_FILE_VERSION)
            throw InputError(where, "unsupported VDB file format version " + std::to_string(version) +
                                        " (this build reads up to " + std::to_string(openvdb::OPENVDB_FILE_VERSION) +
                                        "), or a corrupt file");
        const std::uint64_t fileSize = std::filesystem::file_size(path, ec);
        if (ec) throw InputError(where, "cannot open: " + ec.message());
        const std::string problem = checkVdbLayout(in, fileSize);
        if (!problem.empty()) throw InputError(where, problem);
        in.clear();
        in.seekg(0);
    }

    initializeOpenVdbOnce();
    openvdb::FloatGrid::Ptr grid;
    try {
        // A stream that throws on any short read: a truncated or corrupt file
        // ends in an exception instead of OpenVDB parsing uninitialised data.
        in.exceptions(std::ios::failbit | std::ios::badbit);
        openvdb::io::Stream stream(in, /*delayLoad=*/false);
        const openvdb::GridPtrVecPtr grids = stream.getGrids();
        if (!grids || grids->empty()) throw InputError(where, "no grids in the file");
        if (gridName.empty()) {
            for (const openvdb::GridBase::Ptr& g : *grids) {
                if (g && g->isType<openvdb::FloatGrid>()) {
                    grid = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
                    break;
                }
            }
            if (!grid) throw InputError(where, "no float grid in the file");
        } else {
            openvdb::GridBase::Ptr named;
            for (const openvdb::GridBase::Ptr& g : *grids)
                if (g && g->getName() == gridName) {
                    named = g;
                    break;
                }
            if (!named) {
                std::string names;
                for (const openvdb::GridBase::Ptr& g : *grids)
                    if (g) names += (names.empty() ? "'" : ", '") + g->getName() + "'";
                throw InputError(where, "grid '" + gridName + "' not found (the file has " + names + ")");
            }
            if (!named->isType<openvdb::FloatGrid>())
                throw InputError(where,
                                 "grid '" + gridName + "' holds " + named->valueType() + " values: not a float grid");
            grid = openvdb::gridPtrCast<openvdb::FloatGrid>(named);
        }
    } catch (const InputError&) {
        throw;
    } catch (const std::bad_alloc&) {
        throw InputError(where, "corrupt VDB file (implausible sizes: out of memory while reading)");
    } catch (const std::ios_base::failure&) {
        throw InputError(where, "truncated or corrupt VDB file (unexpected end of data)");
    } catch (const openvdb::Exception& e) {
        throw InputError(where, "cannot read VDB file: " + openVdbReason(e));
    } catch (const std::exception& e) {
        // Anything else thrown while parsing (boost, blosc, zlib wrappers, ...)
        // is a property of the file's bytes, not a bug of ours.
        throw InputError(where, "cannot read VDB file: " + std::string(e.what()));
    }

    const std::string label = "grid '" + grid->getName() + "'";
    if (!grid->transform().isLinear())
        throw InputError(where, label + " has a non-linear (frustum) transform, which is not supported");
    const float background = grid->background();
    if (!std::isfinite(background) || background != 0.f)
        throw InputError(where, label + " has background value " + describeValue(background) +
                                    "; a density grid (fog volume) needs background 0 (level sets are not supported)");
    const std::size_t active = static_cast<std::size_t>(grid->activeVoxelCount());
    if (active == 0) throw InputError(where, label + " is empty (no active voxels)");
    const GridStats stats = analyse(*grid);
    if (!stats.allFinite)
        throw InputError(where, label + " has non-finite density values (e.g. " + describeValue(stats.badValue) +
                                    " at voxel " + describeCoord(stats.badCoord) + ")");
    if (!stats.allNonNegative)
        throw InputError(where, label + " has negative density values (e.g. " + describeValue(stats.badValue) +
                                    " at voxel " + describeCoord(stats.badCoord) + ")");
    const Aabb bounds = worldSupport(grid->transform(), stats.nonZeroIndexBounds);
    if (!bounds.empty() && (!isFinite(bounds.lo) || !isFinite(bounds.hi)))
        throw InputError(where, label + " has non-finite world bounds (degenerate transform)");

    auto impl = std::make_unique<OpenVdbGrid>();
    impl->bounds = bounds;
    impl->maxDensity = stats.maxValue;
    impl->activeVoxels = active;
    impl->name = grid->getName();
    impl->grid = std::move(grid);
    return impl;
}

const openvdb_module::Functions kFunctions{openvdb_module::kAbiVersion, sizeof(VolumeGrid::Impl),
                                           RTLAB_OPENVDB_ABI_TOKEN, makeProceduralFog, loadVdb};

}  // namespace
}  // namespace rtlab::ecs

extern "C" __attribute__((visibility("default"))) const rtlab::ecs::openvdb_module::Functions* rtlab_openvdb_module() {
    return &rtlab::ecs::kFunctions;
}
