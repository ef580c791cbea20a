#pragma once
// Reading an export (format.hpp) and comparing a replay with the model's
// answers: shared by the CUDA program and its host twin.
#include <gpucheck/format.hpp>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace gpucheck {

struct CheckData {
    SceneHeader header{};
    std::vector<MeshInfo> meshes;
    std::vector<InstanceInfo> instances;
    std::vector<std::uint32_t> image;
    std::vector<RayIn> rays;
    std::vector<RayOut> expected;
    std::uint32_t maxStackDepth = 0;  // over the expected rays
};

namespace detail {
inline bool readAll(const std::string& path, std::vector<unsigned char>& bytes, std::string& error) {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) {
        error = path + ": cannot open";
        return false;
    }
    bytes.clear();
    unsigned char buffer[1 << 16];
    std::size_t n;
    while ((n = std::fread(buffer, 1, sizeof buffer, f)) > 0) bytes.insert(bytes.end(), buffer, buffer + n);
    std::fclose(f);
    return true;
}
// Whether `count` records of T follow `at` (checked before anything is allocated for them).
template <class T>
bool fits(const std::vector<unsigned char>& bytes, std::size_t at, std::uint64_t count) {
    return at <= bytes.size() && count <= (bytes.size() - at) / sizeof(T);
}
template <class T>
bool take(const std::vector<unsigned char>& bytes, std::size_t& at, T* out, std::size_t count) {
    if (bytes.size() - at < sizeof(T) * count || at > bytes.size()) return false;
    std::memcpy(static_cast<void*>(out), bytes.data() + at, sizeof(T) * count);
    at += sizeof(T) * count;
    return true;
}
}  // namespace detail

// Reads DIR/scene.bin, rays.bin and expected.bin; false with `error` naming the file and the problem.
inline bool loadCheck(const std::string& dir, CheckData& d, std::string& error) {
    std::vector<unsigned char> bytes;
    std::size_t at = 0;
    const std::string scene = dir + "/scene.bin", rays = dir + "/rays.bin", expected = dir + "/expected.bin";
    if (!detail::readAll(scene, bytes, error)) return false;
    if (!detail::take(bytes, at, &d.header, 1) || std::memcmp(d.header.magic, "RTLGCSCN", 8) != 0 ||
        d.header.version != kFormatVersion || d.header.width < 2 || d.header.width > kMaxWidth ||
        d.header.nodeBytes != 16 + 28 * d.header.width || d.header.imageBytes % 4 != 0) {
        error = scene + ": not a gpucheck scene of format version " + std::to_string(kFormatVersion);
        return false;
    }
    const std::uint64_t tables = at + std::uint64_t(d.header.meshCount) * sizeof(MeshInfo) +
                                 std::uint64_t(d.header.instanceCount) * sizeof(InstanceInfo);
    if (!detail::fits<MeshInfo>(bytes, at, d.header.meshCount) ||
        !detail::fits<InstanceInfo>(bytes, at, d.header.instanceCount) || tables > bytes.size() ||
        !detail::fits<std::uint32_t>(bytes, static_cast<std::size_t>(tables), d.header.imageBytes / 4)) {
        error = scene + ": truncated or of the wrong size";
        return false;
    }
    d.meshes.resize(d.header.meshCount);
    d.instances.resize(d.header.instanceCount);
    d.image.resize(d.header.imageBytes / 4);
    if (!detail::take(bytes, at, d.meshes.data(), d.meshes.size()) ||
        !detail::take(bytes, at, d.instances.data(), d.instances.size()) ||
        !detail::take(bytes, at, d.image.data(), d.image.size()) || at != bytes.size()) {
        error = scene + ": truncated or of the wrong size";
        return false;
    }
    RaysHeader rh{};
    at = 0;
    if (!detail::readAll(rays, bytes, error)) return false;
    if (!detail::take(bytes, at, &rh, 1) || std::memcmp(rh.magic, "RTLGCRAY", 8) != 0 || rh.version != kFormatVersion) {
        error = rays + ": not a gpucheck ray file";
        return false;
    }
    if (rh.exportId != d.header.exportId) {
        error = rays + ": not of the same export as scene.bin";
        return false;
    }
    if (!detail::fits<RayIn>(bytes, at, rh.rayCount)) {
        error = rays + ": truncated or of the wrong size";
        return false;
    }
    d.rays.resize(rh.rayCount);
    if (!detail::take(bytes, at, d.rays.data(), d.rays.size()) || at != bytes.size()) {
        error = rays + ": truncated or of the wrong size";
        return false;
    }
    ExpectedHeader eh{};
    at = 0;
    if (!detail::readAll(expected, bytes, error)) return false;
    if (!detail::take(bytes, at, &eh, 1) || std::memcmp(eh.magic, "RTLGCEXP", 8) != 0 || eh.version != kFormatVersion ||
        eh.rayCount != rh.rayCount || eh.exportId != rh.exportId || !detail::fits<RayOut>(bytes, at, eh.rayCount)) {
        error = expected + ": not the expected answers of these rays";
        return false;
    }
    d.expected.resize(eh.rayCount);
    if (!detail::take(bytes, at, d.expected.data(), d.expected.size()) || at != bytes.size()) {
        error = expected + ": truncated or of the wrong size";
        return false;
    }
    d.maxStackDepth = 0;
    for (const RayOut& e : d.expected)
        d.maxStackDepth = e.maxStackDepth > d.maxStackDepth ? e.maxStackDepth : d.maxStackDepth;
    if (d.maxStackDepth > kMaxStackDepth) {
        error = expected + ": a stack deeper than any BVH of the model has";
        return false;
    }
    return true;
}

// Rays whose answer differs from the model's in any bit (hit, t, barycentrics,
// ids, counters, fetched bytes, sectors, checksum); the first few are printed.
inline std::uint64_t compareWithModel(const std::vector<RayOut>& got, const std::vector<RayOut>& expected,
                                      int printLimit = 5) {
    std::uint64_t mismatches = 0;
    for (std::size_t i = 0; i < got.size(); ++i) {
        if (std::memcmp(&got[i], &expected[i], sizeof(RayOut)) == 0) continue;
        if (static_cast<int>(mismatches++) < printLimit) {
            const RayOut& g = got[i];
            const RayOut& e = expected[i];
            std::fprintf(stderr,
                         "gpucheck: ray %zu differs: hit %u/%u t %.9g/%.9g prim %u/%u inst %u/%u nodes %u/%u "
                         "leaves %u/%u tris %u/%u steps %u/%u bytes %u/%u checksum %08x/%08x (got/model)\n",
                         i, g.hit, e.hit, g.t, e.t, g.primitive, e.primitive, g.instance, e.instance, g.nodeVisits,
                         e.nodeVisits, g.leafVisits, e.leafVisits, g.triangleTests, e.triangleTests, g.steps, e.steps,
                         g.fetchBytes, e.fetchBytes, g.checksum, e.checksum);
        }
    }
    return mismatches;
}

}  // namespace gpucheck
