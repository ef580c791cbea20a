#pragma once
// The RT-core model's own BVH (docs/rtcore-model.md, "BVH"). The topology
// comes from Embree's builder (rtcBuildBVH: SAH, branching factor = width,
// leaf size), flattened into plain arrays the model traverses and refits:
//
//   nodes   N-wide internal nodes in depth-first pre-order (a parent always
//           precedes its children); each holds its children's float AABBs
//           and references (internal node or leaf)
//   leaves  ranges of primitive references, in depth-first order
//   refs    (geometry, primitive) per leaf slot; BLAS: triangle of a mesh
//           geometry, TLAS: instance index
//
// The layout depends only on the input and the parameters: the builder runs
// on one thread (a task arena of size 1) and leaf references are sorted, so
// two builds of the same input give identical arrays, whatever the thread
// count of the process.
#include <rtlab/core/math.hpp>
#include <rtlab/ecs/assets.hpp>
#include <rtlab/rtcore_sim/config.hpp>

#include <embree3/rtcore.h>

#include <array>
#include <cstdint>
#include <vector>

namespace rtlab::rtcore_sim {

inline constexpr std::uint32_t kMaxBvhWidth = 8;

// A child reference: an internal node index or a leaf index, or nothing.
struct NodeRef {
    static constexpr std::uint32_t kLeafBit = 0x80000000u;
    static constexpr std::uint32_t kInvalid = 0xffffffffu;
    std::uint32_t bits = kInvalid;

    static NodeRef node(std::uint32_t index) { return {index}; }
    static NodeRef leaf(std::uint32_t index) { return {index | kLeafBit}; }
    bool valid() const { return bits != kInvalid; }
    bool isLeaf() const { return valid() && (bits & kLeafBit) != 0; }
    bool isNode() const { return valid() && (bits & kLeafBit) == 0; }
    std::uint32_t index() const { return bits & ~kLeafBit; }
    friend bool operator==(NodeRef a, NodeRef b) = default;
};

// An internal node with 2..width children; slots >= childCount are unused.
struct BvhNode {
    std::uint32_t childCount = 0;
    std::array<NodeRef, kMaxBvhWidth> children{};
    std::array<Aabb, kMaxBvhWidth> childBounds{};
    Aabb bounds() const;  // union of the child boxes
};

struct BvhLeaf {
    std::uint32_t firstRef = 0;
    std::uint32_t refCount = 0;
};

// A leaf slot: BLAS (geometry index in the mesh, triangle index); TLAS
// (0, instance index).
struct PrimitiveRef {
    std::uint32_t geometry = 0;
    std::uint32_t primitive = 0;
    friend bool operator==(PrimitiveRef a, PrimitiveRef b) = default;
    friend auto operator<=>(PrimitiveRef a, PrimitiveRef b) = default;
};

struct Bvh {
    std::uint32_t width = 0;
    NodeRef root;  // invalid when there is nothing to build over; a leaf when everything fits in one
    Aabb rootBounds;
    std::vector<BvhNode> nodes;
    std::vector<BvhLeaf> leaves;
    std::vector<PrimitiveRef> refs;

    bool empty() const { return !root.valid(); }
    std::uint32_t depth() const;  // levels of internal nodes plus one for the leaves; 0 when empty
    // SAH cost relative to the root: traversalCost * sum(area(node)) +
    // intersectionCost * sum(area(leaf) * refs), over area(root).
    double sahCost(float traversalCost, float intersectionCost) const;
};

// A build input: one primitive's bounds and its reference.
struct BuildPrimitive {
    Aabb bounds;
    PrimitiveRef ref;
};

// Parameters of one rtcBuildBVH call.
struct BuildSettings {
    std::uint32_t width = 6;
    std::uint32_t maxLeafSize = 4;
    BuildQuality quality = BuildQuality::Medium;
    float traversalCost = 1.f;
    float intersectionCost = 1.f;
};

// Clips primitive `ref` (whose current reference box is `bounds`) at
// `position` along `axis`; the result boxes lie within `bounds`. Used for
// spatial splits (BuildQuality::High).
class PrimitiveSplitter {
public:
    virtual ~PrimitiveSplitter() = default;
    virtual void split(const PrimitiveRef& ref, const Aabb& bounds, int axis, float position, Aabb& left,
                       Aabb& right) const = 0;
};

// Runs Embree's BVH builder into the model's layout.
class BvhBuilder {
public:
    explicit BvhBuilder(RTCDevice device) : device_(device) {}
    // `splitter` enables spatial splits when settings.quality is High;
    // without one, High builds like Medium (Embree's own rule).
    Bvh build(const std::vector<BuildPrimitive>& primitives, const BuildSettings& settings,
              const PrimitiveSplitter* splitter = nullptr) const;

private:
    RTCDevice device_;
};

// A leaf slot's data as a leaf fetch reads it: a triangle's object-space
// vertices, or for a procedural reference its AABB (v[0] = lo, v[1] = hi,
// v[2] unused).
struct Triangle {
    std::array<vec3, 3> v;
};

// One mesh's bottom-level BVH: the triangles of its triangle geometries and
// the AABBs of its procedural geometries (leaf references (geometry index,
// box index)); a leaf may hold both kinds.
struct Blas {
    Bvh bvh;
    std::vector<Triangle> triangles;              // one per bvh.refs entry (same order)
    std::vector<std::uint32_t> triangleCounts;    // per geometry at build time (0 for procedural)
    std::vector<std::uint32_t> proceduralCounts;  // per geometry: AABB count at build time (0 for triangles)
    bool hasProcedural = false;                   // some geometry is procedural
    double buildSahCost = 0.0;
    bool spatialSplits = false;
    float magnitude = 0.f;  // largest |object coordinate| of the root box (conservative padding)

    bool isProcedural(const PrimitiveRef& ref) const { return hasProcedural && proceduralCounts[ref.geometry] != 0; }
    Aabb proceduralBox(std::size_t refIndex) const { return Aabb{triangles[refIndex].v[0], triangles[refIndex].v[1]}; }
};

BuildSettings blasBuildSettings(const BvhParams& params);
BuildSettings tlasBuildSettings(const BvhParams& params);

// Builds the BLAS of `mesh`. Triangles with non-finite vertices and empty or
// non-finite procedural boxes are left out (Embree ignores them too). Spatial splits (High) apply to rigid meshes
// only: a deformable mesh is built as Medium so that refits stay tight.
Blas buildBlas(const BvhBuilder& builder, const ecs::MeshAsset& mesh, const BvhParams& params);

// Bottom-up refit after the vertices moved (same topology): re-reads every
// referenced triangle and recomputes every child box from the leaves up.
// Throws std::invalid_argument when the triangle counts changed.
void refitBlas(Blas& blas, const ecs::MeshAsset& mesh);

}  // namespace rtlab::rtcore_sim
