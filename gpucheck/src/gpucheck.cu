// gpucheck EXPORT_DIR [--repeat N] [--io-only] [--blocks-per-sm B] [--json FILE]
//
// Replays the rays of an export (rtlab gpucheck-export) on an NVIDIA GPU,
// one thread per ray, with the model's traversal (traversal.hpp) over the
// model's BVH bytes, and checks every ray's hit, per-ray work and fetch
// checksum against the model's (exit 1 on any difference). Reports rays/s
// (median of --repeat timed launches, CUDA events). --io-only runs instead a
// kernel that reads the rays and writes answers of the same size without
// traversing: its counters are subtracted from the traversal's
// (perf/gpucheck.sh), so that what remains is the BVH fetch stream: the
// same traversal kernel over an empty scene (every ray ends before its first
// fetch), so its code, its ray loads and its answer stores are the same.
// Exit 1: some ray differs from the model; 2: unreadable or corrupt input, or
// a scene over the constant-memory tables; 3: a CUDA error, or the kernel
// did not get the occupancy it was sized for.
#include <gpucheck/files.hpp>
#include <gpucheck/traversal.hpp>

#include <cuda_runtime.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace {

constexpr int kBlock = 64;          // threads per block
constexpr int kSharedEntries = 32;  // stack entries per thread in shared memory (the rest in global memory)
constexpr unsigned kMaxInstances = 600;
constexpr unsigned kMaxMeshes = 256;

__constant__ gpucheck::InstanceInfo cInstances[kMaxInstances];
__constant__ gpucheck::MeshInfo cMeshes[kMaxMeshes];

struct ConstantTables {
    __device__ const gpucheck::MeshInfo& mesh(std::uint32_t i) const { return cMeshes[i]; }
    __device__ const gpucheck::InstanceInfo& instance(std::uint32_t i) const { return cInstances[i]; }
};

// A thread's stack: the first kSharedEntries entries in shared memory
// (strided by the block size: no bank conflicts), deeper ones in a
// per-thread region of global memory (counted: that traffic is not the BVH's).
struct DeviceStack {
    std::uint32_t (*bits)[kBlock];
    float (*ts)[kBlock];
    std::uint8_t (*kinds)[kBlock];
    std::uint32_t* overflow;  // 3 words per entry
    unsigned long long* overflowPushes;
    unsigned tid;
    std::uint32_t n;
    std::uint32_t overflowEntries;  // room in global memory: the model's deepest stack, less the shared entries
    __device__ bool push(std::uint32_t b, float t, std::uint32_t kind) {
        if (n >= kSharedEntries + overflowEntries) return false;  // deeper than the model's deepest: corrupt
        if (n < kSharedEntries) {
            bits[n][tid] = b;
            ts[n][tid] = t;
            kinds[n][tid] = static_cast<std::uint8_t>(kind);
        } else {
            std::uint32_t* e = overflow + 3 * (n - kSharedEntries);
            e[0] = b;
            e[1] = __float_as_uint(t);
            e[2] = kind;
            atomicAdd(overflowPushes, 1ull);
        }
        ++n;
        return true;
    }
    __device__ void pop(std::uint32_t& b, float& t, std::uint32_t& kind) {
        --n;
        if (n < kSharedEntries) {
            b = bits[n][tid];
            t = ts[n][tid];
            kind = kinds[n][tid];
        } else {
            const std::uint32_t* e = overflow + 3 * (n - kSharedEntries);
            b = e[0];
            t = __uint_as_float(e[1]);
            kind = e[2];
        }
    }
    __device__ void clear() { n = 0; }
};

__global__ void __launch_bounds__(kBlock)
    traverse(gpucheck::SceneView scene, const gpucheck::RayIn* rays, gpucheck::RayOut* out, std::uint32_t count,
             std::uint32_t* overflow, std::uint32_t overflowEntries, unsigned long long* overflowPushes,
             unsigned* corruptRays) {
    __shared__ std::uint32_t bits[kSharedEntries][kBlock];
    __shared__ float ts[kSharedEntries][kBlock];
    __shared__ std::uint8_t kinds[kSharedEntries][kBlock];
    const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
    if (i >= count) return;
    DeviceStack stack{bits,           ts,          kinds, overflow + std::size_t(3) * overflowEntries * i,
                      overflowPushes, threadIdx.x, 0,     overflowEntries};
    const gpucheck::RayIn ray = rays[i];
    gpucheck::RayOut o;
    if (!gpucheck::traceRay(scene, ConstantTables{}, ray, stack, o)) atomicAdd(corruptRays, 1u);
    out[i] = o;
}

// A string for the JSON summary: quotes, backslashes and control characters escaped.
std::string jsonText(const std::string& s) {
    std::string out;
    for (const char c : s) {
        if (c == '"' || c == '\\') out += '\\';
        if (static_cast<unsigned char>(c) < 0x20) out += ' ';
        else out += c;
    }
    return out;
}

#define CHECK(call)                                                                           \
    do {                                                                                      \
        const cudaError_t e_ = (call);                                                        \
        if (e_ != cudaSuccess) {                                                              \
            std::fprintf(stderr, "gpucheck: %s failed: %s\n", #call, cudaGetErrorString(e_)); \
            std::exit(1);                                                                     \
        }                                                                                     \
    } while (0)

}  // namespace

int main(int argc, char** argv) {
    std::string dir, jsonPath;
    int repeat = 10;
    bool ioOnly = false;
    int wantBlocksPerSm = 0;  // 0: as many as fit
    for (int a = 1; a < argc; ++a) {
        const std::string arg = argv[a];
        if (arg == "--repeat" && a + 1 < argc) repeat = std::max(1, std::atoi(argv[++a]));
        else if (arg == "--io-only") ioOnly = true;
        else if (arg == "--blocks-per-sm" && a + 1 < argc) wantBlocksPerSm = std::max(1, std::atoi(argv[++a]));
        else if (arg == "--json" && a + 1 < argc) jsonPath = argv[++a];
        else if (dir.empty() && arg[0] != '-') dir = arg;
        else {
            std::fprintf(stderr,
                         "usage: gpucheck EXPORT_DIR [--repeat N] [--io-only] [--blocks-per-sm B] [--json FILE]\n");
            return 2;
        }
    }
    if (dir.empty()) {
        std::fprintf(stderr, "usage: gpucheck EXPORT_DIR [--repeat N] [--io-only] [--blocks-per-sm B] [--json FILE]\n");
        return 2;
    }
    gpucheck::CheckData d;
    std::string error;
    if (!gpucheck::loadCheck(dir, d, error)) {
        std::fprintf(stderr, "gpucheck: %s\n", error.c_str());
        return 2;
    }
    if (d.instances.size() > kMaxInstances || d.meshes.size() > kMaxMeshes) {
        std::fprintf(stderr, "gpucheck: %s: %zu instances and %zu meshes; the constant tables hold %u and %u\n",
                     dir.c_str(), d.instances.size(), d.meshes.size(), kMaxInstances, kMaxMeshes);
        return 2;
    }
    const std::uint32_t n = static_cast<std::uint32_t>(d.rays.size());
    const std::uint32_t overflowEntries = d.maxStackDepth > kSharedEntries ? d.maxStackDepth - kSharedEntries : 0;

    // Step: upload the image, the tables and the rays.
    cudaDeviceProp prop{};
    CHECK(cudaGetDeviceProperties(&prop, 0));
    int driver = 0, runtime = 0;
    CHECK(cudaDriverGetVersion(&driver));
    CHECK(cudaRuntimeGetVersion(&runtime));
    std::uint32_t *image = nullptr, *overflow = nullptr;
    gpucheck::RayIn* rays = nullptr;
    gpucheck::RayOut* out = nullptr;
    unsigned long long* overflowPushes = nullptr;
    unsigned* corruptRays = nullptr;
    CHECK(cudaMalloc(&image, d.image.size() * 4 + 4));
    CHECK(cudaMemcpy(image, d.image.data(), d.image.size() * 4, cudaMemcpyHostToDevice));
    if (!d.instances.empty())
        CHECK(cudaMemcpyToSymbol(cInstances, d.instances.data(), d.instances.size() * sizeof(gpucheck::InstanceInfo)));
    if (!d.meshes.empty())
        CHECK(cudaMemcpyToSymbol(cMeshes, d.meshes.data(), d.meshes.size() * sizeof(gpucheck::MeshInfo)));
    CHECK(cudaMalloc(&rays, std::size_t(n) * sizeof(gpucheck::RayIn)));
    CHECK(cudaMemcpy(rays, d.rays.data(), std::size_t(n) * sizeof(gpucheck::RayIn), cudaMemcpyHostToDevice));
    CHECK(cudaMalloc(&out, std::size_t(n) * sizeof(gpucheck::RayOut)));
    CHECK(cudaMalloc(&overflow, std::size_t(3) * 4 * std::max<std::uint32_t>(overflowEntries, 1) * n));
    CHECK(cudaMalloc(&overflowPushes, sizeof(unsigned long long)));
    CHECK(cudaMalloc(&corruptRays, sizeof(unsigned)));
    CHECK(cudaMemset(corruptRays, 0, sizeof(unsigned)));
    // Shared memory for as many blocks as the registers allow (each block's static shared memory
    // plus the runtime's reserve); the rest of each SM's unified 256 KB is L1 (its size as
    // configured is read by ncu: launch__shared_mem_config_size). The occupancy is checked after.
    int blocksPerSm = 0;
    CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocksPerSm, traverse, kBlock, 0));
    cudaFuncAttributes attributes{};
    CHECK(cudaFuncGetAttributes(&attributes, traverse));
    const int sharedPerBlock = static_cast<int>(attributes.sharedSizeBytes + prop.reservedSharedMemPerBlock);
    const int sharedPerSm = static_cast<int>(prop.sharedMemPerMultiprocessor);
    const int carveout = std::min(100, (blocksPerSm * sharedPerBlock * 100 + sharedPerSm - 1) / sharedPerSm);
    CHECK(cudaFuncSetAttribute(traverse, cudaFuncAttributePreferredSharedMemoryCarveout, carveout));
    int blocksAfter = 0;
    CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocksAfter, traverse, kBlock, 0));
    if (blocksAfter != blocksPerSm) {
        std::fprintf(stderr, "gpucheck: the carve-out of %d%% leaves %d blocks per SM instead of %d\n", carveout,
                     blocksAfter, blocksPerSm);
        return 3;
    }
    // --blocks-per-sm B: fewer resident blocks (rays in flight) with the same L1: each block
    // reserves dynamic shared memory so that B of them fill what the full occupancy used.
    int dynamicShared = 0;
    if (wantBlocksPerSm > 0 && wantBlocksPerSm < blocksPerSm) {
        dynamicShared = blocksPerSm * sharedPerBlock / wantBlocksPerSm - sharedPerBlock;
        CHECK(cudaFuncSetAttribute(traverse, cudaFuncAttributeMaxDynamicSharedMemorySize, dynamicShared));
        int blocksWith = 0;
        CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocksWith, traverse, kBlock, dynamicShared));
        if (blocksWith != wantBlocksPerSm) {
            std::fprintf(stderr, "gpucheck: %d bytes of dynamic shared memory give %d blocks per SM, not %d\n",
                         dynamicShared, blocksWith, wantBlocksPerSm);
            return 3;
        }
        blocksPerSm = blocksWith;
    }
    // --io-only: the same kernel over an empty scene (no fetch at all).
    gpucheck::SceneHeader header = d.header;
    if (ioOnly) header.tlasRoot = gpucheck::kInvalidRef;
    const gpucheck::SceneView scene{image, header};
    const unsigned blocks = (n + kBlock - 1) / kBlock;

    // Step: timed launches (the first is the warm-up), the answers poisoned before each.
    cudaEvent_t start, stop;
    CHECK(cudaEventCreate(&start));
    CHECK(cudaEventCreate(&stop));
    std::vector<float> ms;
    for (int r = 0; r <= repeat; ++r) {
        CHECK(cudaMemset(out, 0xff, std::size_t(n) * sizeof(gpucheck::RayOut)));
        CHECK(cudaMemset(overflowPushes, 0, sizeof(unsigned long long)));
        CHECK(cudaEventRecord(start));
        traverse<<<blocks, kBlock, dynamicShared>>>(scene, rays, out, n, overflow, overflowEntries, overflowPushes,
                                                    corruptRays);
        CHECK(cudaGetLastError());
        CHECK(cudaEventRecord(stop));
        CHECK(cudaEventSynchronize(stop));
        float t = 0.f;
        CHECK(cudaEventElapsedTime(&t, start, stop));
        if (r > 0 || repeat == 0) ms.push_back(t);
    }
    if (ms.empty()) ms.push_back(0.f);
    std::sort(ms.begin(), ms.end());
    const float median = ms[ms.size() / 2];

    // Step: every ray against the model.
    std::vector<gpucheck::RayOut> got(n);
    CHECK(cudaMemcpy(got.data(), out, std::size_t(n) * sizeof(gpucheck::RayOut), cudaMemcpyDeviceToHost));
    unsigned long long pushes = 0;
    CHECK(cudaMemcpy(&pushes, overflowPushes, sizeof pushes, cudaMemcpyDeviceToHost));
    unsigned corrupt = 0;
    CHECK(cudaMemcpy(&corrupt, corruptRays, sizeof corrupt, cudaMemcpyDeviceToHost));
    if (corrupt) {
        std::fprintf(stderr, "gpucheck: %s: %u rays meet a corrupt memory image\n", dir.c_str(), corrupt);
        return 2;
    }
    const std::uint64_t mismatches = ioOnly ? 0 : gpucheck::compareWithModel(got, d.expected);
    const double raysPerSecond = median > 0.f ? double(n) / (double(median) * 1e-3) : 0.0;
    std::printf(
        "gpucheck: %s: %u rays on %s, %s kernel %.3f ms (median of %zu), %.4g rays/s, %llu stack "
        "entries beyond shared memory, %llu differ from the model\n",
        dir.c_str(), n, prop.name, ioOnly ? "io-only" : "traversal", median, ms.size(), raysPerSecond, pushes,
        static_cast<unsigned long long>(mismatches));
    if (!jsonPath.empty()) {
        std::FILE* f = std::fopen(jsonPath.c_str(), "w");
        if (!f) {
            std::fprintf(stderr, "gpucheck: cannot write %s\n", jsonPath.c_str());
            return 2;
        }
        std::fprintf(
            f,
            "{\"export\": \"%s\", \"rays\": %u, \"kernel\": \"%s\", \"device\": \"%s\", \"sms\": %d, "
            "\"l2Bytes\": %d, \"driverVersion\": %d, \"runtimeVersion\": %d, \"blockThreads\": %d, "
            "\"sharedStackEntries\": %d, \"medianMs\": %.6f, \"timedLaunches\": %zu, \"raysPerSecond\": %.6g, "
            "\"stackOverflowPushes\": %llu, \"mismatches\": %llu, \"blocksPerSm\": %d, \"carveoutPercent\": %d}\n",
            jsonText(dir).c_str(), n, ioOnly ? "traverse (empty scene)" : "traverse", jsonText(prop.name).c_str(),
            prop.multiProcessorCount, prop.l2CacheSize, driver, runtime, kBlock, kSharedEntries, median, ms.size(),
            raysPerSecond, pushes, static_cast<unsigned long long>(mismatches), blocksPerSm, carveout);
        std::fclose(f);
    }
    CHECK(cudaFree(image));
    CHECK(cudaFree(rays));
    CHECK(cudaFree(out));
    CHECK(cudaFree(overflow));
    CHECK(cudaFree(overflowPushes));
    CHECK(cudaFree(corruptRays));
    return mismatches ? 1 : 0;
}
