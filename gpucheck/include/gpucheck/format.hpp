#pragma once
// The files `rtlab gpucheck-export` writes and the GPU check reads
// (docs/validation.md, "Files"). Plain little-endian records, no
// dependencies: the CUDA program builds from the CUDA toolkit alone.
//
//   scene.bin     SceneHeader, MeshInfo[meshCount], InstanceInfo[instanceCount],
//                 then the model's memory image (imageBytes): the TLAS, the
//                 instance table and the BLASes at exactly the addresses the
//                 timing model's node cache sees (rtcore_sim::MemoryLayout),
//                 with these contents:
//       internal node  u32 childCount, 12 reserved bytes, then width children:
//                      float lo[3], float hi[3], u32 reference
//                      (node: its index; leaf: kLeafBit | byte offset of the
//                      leaf from the region's leaf base; unused: kInvalidRef)
//       TLAS leaf      u32 refCount, u32 0, then per reference
//                      u32 (instance index | instance mask << 24)
//       BLAS leaf      u32 refCount, u32 0, then per slot float v0[3], v1[3],
//                      v2[3], u32 geometry, u32 primitive
//       instance       float worldFromObject[3][4] (rows), u32 mesh, u32 mask,
//                      u32 flags (0), u32 instance index
//   rays.bin      RaysHeader, RayIn[rayCount]
//   expected.bin  ExpectedHeader, RayOut[rayCount]: the model's answer
//   model.json    the model's prediction for the same launch, the selection
//                 and the configuration
#include <cstdint>

namespace gpucheck {

inline constexpr std::uint32_t kFormatVersion = 1;
inline constexpr std::uint32_t kLeafBit = 0x80000000u;
inline constexpr std::uint32_t kInvalidRef = 0xffffffffu;
inline constexpr std::uint32_t kMaxWidth = 8;
inline constexpr std::uint32_t kMaxTlasLeafRefs = 32;
inline constexpr std::uint32_t kInstanceIndexBits = 24;
// The model's stack bound (rtcore_sim::kStackCapacity: (8 - 1) x 2 x 41 + 32 + 1 entries).
inline constexpr std::uint32_t kMaxStackDepth = 607;

struct SceneHeader {
    char magic[8];  // "RTLGCSCN"
    std::uint32_t version;
    std::uint32_t width;      // BVH width (children per node)
    std::uint32_t nodeBytes;  // 16 + 28 x width
    std::uint32_t meshCount;
    std::uint32_t instanceCount;
    std::uint32_t tlasRoot;  // reference bits of the TLAS root (kInvalidRef: empty scene)
    std::uint64_t imageBytes;
    std::uint64_t tlasNodeBase, tlasLeafBase, instanceBase;
    float tlasMagnitude, tlasConditioning;  // conservative TLAS padding (tracer/conservative_bounds.hpp)
    float farScale;                         // the slab test's 1 + 2 gamma(3)
    std::uint32_t exportId;                 // the same in the three files of one export (a hash of its rays and image)
};
static_assert(sizeof(SceneHeader) == 80);

struct MeshInfo {
    std::uint64_t nodeBase, leafBase;
    std::uint32_t root;  // kInvalidRef: no BLAS (never built or empty)
    float magnitude;     // conservative BLAS padding
};
static_assert(sizeof(MeshInfo) == 24);

// The exact instance transform the model applies (in double precision,
// rounded once to float): objectFromWorld[column][row], columns 0..3, rows 0..2.
struct InstanceInfo {
    double objectFromWorld[4][3];
};
static_assert(sizeof(InstanceInfo) == 96);

// How a ray's candidates are decided (from the recorded verdicts).
enum Policy : std::uint32_t {
    kCommitAll = 0,  // every candidate committed (opaque closest hit)
    kFirstHit = 1,   // the first candidate committed and the search ended (shadow, AO)
};

struct RaysHeader {
    char magic[8];  // "RTLGCRAY"
    std::uint32_t version;
    std::uint32_t rayCount;
    std::uint32_t exportId;
    std::uint32_t reserved;
};
static_assert(sizeof(RaysHeader) == 24);

struct RayIn {
    float origin[3];
    float tMin;
    float direction[3];
    float tMax;
    std::uint32_t mask;           // instance inclusion mask (low 8 bits)
    std::uint32_t policy;         // Policy
    std::uint32_t skipTriangles;  // 1: triangles are not tested (DXR SKIP_TRIANGLES)
    std::uint32_t reserved;
};
static_assert(sizeof(RayIn) == 48);

struct ExpectedHeader {
    char magic[8];  // "RTLGCEXP"
    std::uint32_t version;
    std::uint32_t rayCount;
    std::uint32_t exportId;
    std::uint32_t reserved;
};
static_assert(sizeof(ExpectedHeader) == 24);

// One ray's answer: its committed hit and the work its traversal did.
struct RayOut {
    float t, b1, b2;  // committed hit (t = +inf, b = 0 on a miss)
    std::uint32_t hit;
    std::uint32_t instance, geometry, primitive;
    std::uint32_t steps, nodeVisits, leafVisits, triangleTests, instanceTransitions;
    std::uint32_t maxStackDepth;
    std::uint32_t fetchBytes;    // bytes of the node, leaf and instance fetches
    std::uint32_t fetchSectors;  // 32-byte sectors those fetches touch (each fetch on its own)
    std::uint32_t checksum;      // FNV-1a (32-bit) over every fetched 32-bit word, in fetch order
};
static_assert(sizeof(RayOut) == 64);

}  // namespace gpucheck
