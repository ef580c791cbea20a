// Embree's builder (rtcBuildBVH) into the model's flat BVH layout, and the
// bottom-up refit.
#include <rtlab/rtcore_sim/bvh.hpp>
#include <rtlab/tracer/conservative_bounds.hpp>

#include <embree3/rtcore_builder.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstddef>
#include <new>
#include <stdexcept>
#include <string>

namespace rtlab::rtcore_sim {
namespace {

// Embree's spatial-split builder keeps split counters in the top bits of geomID.
constexpr std::uint32_t kSpatialSplitGeomIdMask = 0xffffffffu >> 5;
// Deeper than any SAH tree of the scenes we build; Embree forces leaves
// (fallback splits) before reaching it.
constexpr unsigned kMaxBuildDepth = 40;

Aabb toAabb(const RTCBounds& b) {
    return Aabb{vec3(b.lower_x, b.lower_y, b.lower_z), vec3(b.upper_x, b.upper_y, b.upper_z)};
}

RTCBounds toRtcBounds(const Aabb& b) {
    RTCBounds r{};
    r.lower_x = b.lo.x;
    r.lower_y = b.lo.y;
    r.lower_z = b.lo.z;
    r.upper_x = b.hi.x;
    r.upper_y = b.hi.y;
    r.upper_z = b.hi.z;
    return r;
}

Aabb intersectBoxes(const Aabb& a, const Aabb& b) { return Aabb{glm::max(a.lo, b.lo), glm::min(a.hi, b.hi)}; }

// Temporary tree the Embree callbacks build (memory from Embree's
// thread-local allocator, freed with the RTCBVH); flattened afterwards.
struct TempNode {
    bool isLeaf = false;
    std::uint32_t childCount = 0;
    std::array<const TempNode*, kMaxBvhWidth> children{};
    std::array<Aabb, kMaxBvhWidth> bounds{};
};
struct TempLeaf {
    bool isLeaf = true;
    std::uint32_t count = 0;
    PrimitiveRef* refs = nullptr;
};
static_assert(offsetof(TempNode, isLeaf) == 0 && offsetof(TempLeaf, isLeaf) == 0);

struct BuildContext {
    const PrimitiveSplitter* splitter = nullptr;
    bool spatialSplits = false;
};

void* createNode(RTCThreadLocalAllocator alloc, unsigned childCount, void*) {
    void* mem = rtcThreadLocalAlloc(alloc, sizeof(TempNode), alignof(TempNode));
    auto* node = new (mem) TempNode{};
    node->childCount = childCount;
    return node;
}

void setNodeChildren(void* nodePtr, void** children, unsigned childCount, void*) {
    auto* node = static_cast<TempNode*>(nodePtr);
    for (unsigned i = 0; i < childCount; ++i) node->children[i] = static_cast<const TempNode*>(children[i]);
}

void setNodeBounds(void* nodePtr, const RTCBounds** bounds, unsigned childCount, void*) {
    auto* node = static_cast<TempNode*>(nodePtr);
    for (unsigned i = 0; i < childCount; ++i) node->bounds[i] = toAabb(*bounds[i]);
}

void* createLeaf(RTCThreadLocalAllocator alloc, const RTCBuildPrimitive* prims, size_t count, void* userPtr) {
    const auto& ctx = *static_cast<const BuildContext*>(userPtr);
    void* mem = rtcThreadLocalAlloc(alloc, sizeof(TempLeaf), alignof(TempLeaf));
    auto* leaf = new (mem) TempLeaf{};
    leaf->count = static_cast<std::uint32_t>(count);
    leaf->refs = static_cast<PrimitiveRef*>(
        rtcThreadLocalAlloc(alloc, sizeof(PrimitiveRef) * std::max<size_t>(count, 1), alignof(PrimitiveRef)));
    for (size_t i = 0; i < count; ++i) {
        const std::uint32_t geom = ctx.spatialSplits ? (prims[i].geomID & kSpatialSplitGeomIdMask) : prims[i].geomID;
        leaf->refs[i] = PrimitiveRef{geom, prims[i].primID};
    }
    return leaf;
}

void splitPrimitive(const RTCBuildPrimitive* prim, unsigned axis, float position, RTCBounds* left, RTCBounds* right,
                    void* userPtr) {
    const auto& ctx = *static_cast<const BuildContext*>(userPtr);
    const Aabb current{vec3(prim->lower_x, prim->lower_y, prim->lower_z),
                       vec3(prim->upper_x, prim->upper_y, prim->upper_z)};
    Aabb l, r;
    ctx.splitter->split(PrimitiveRef{prim->geomID & kSpatialSplitGeomIdMask, prim->primID}, current,
                        static_cast<int>(axis), position, l, r);
    *left = toRtcBounds(l);
    *right = toRtcBounds(r);
}

// Depth-first pre-order flattening; leaf references sorted for determinism.
NodeRef flatten(const void* tempPtr, Bvh& bvh) {
    if (static_cast<const TempLeaf*>(tempPtr)->isLeaf) {
        const auto* leaf = static_cast<const TempLeaf*>(tempPtr);
        std::vector<PrimitiveRef> refs(leaf->refs, leaf->refs + leaf->count);
        std::sort(refs.begin(), refs.end());
        refs.erase(std::unique(refs.begin(), refs.end()), refs.end());
        const auto index = static_cast<std::uint32_t>(bvh.leaves.size());
        bvh.leaves.push_back(
            BvhLeaf{static_cast<std::uint32_t>(bvh.refs.size()), static_cast<std::uint32_t>(refs.size())});
        bvh.refs.insert(bvh.refs.end(), refs.begin(), refs.end());
        return NodeRef::leaf(index);
    }
    const auto* temp = static_cast<const TempNode*>(tempPtr);
    const auto index = static_cast<std::uint32_t>(bvh.nodes.size());
    bvh.nodes.emplace_back();
    bvh.nodes[index].childCount = temp->childCount;
    for (std::uint32_t i = 0; i < temp->childCount; ++i) {
        const NodeRef child = flatten(temp->children[i], bvh);  // may grow bvh.nodes
        bvh.nodes[index].children[i] = child;
        bvh.nodes[index].childBounds[i] = temp->bounds[i];
    }
    return NodeRef::node(index);
}

RTCBuildQuality toRtcQuality(BuildQuality q) {
    switch (q) {
        case BuildQuality::Low: return RTC_BUILD_QUALITY_LOW;
        case BuildQuality::Medium: return RTC_BUILD_QUALITY_MEDIUM;
        case BuildQuality::High: return RTC_BUILD_QUALITY_HIGH;
    }
    return RTC_BUILD_QUALITY_MEDIUM;
}

std::uint32_t depthOf(const Bvh& bvh, NodeRef ref) {
    if (!ref.valid()) return 0;
    if (ref.isLeaf()) return 1;
    std::uint32_t d = 0;
    const BvhNode& node = bvh.nodes[ref.index()];
    for (std::uint32_t i = 0; i < node.childCount; ++i) d = std::max(d, depthOf(bvh, node.children[i]));
    return d + 1;
}

bool finiteTriangle(const ecs::Geometry& g, std::size_t t) {
    for (int k = 0; k < 3; ++k) {
        const std::uint32_t i = g.indices[3 * t + k];
        if (i >= g.positions.size() || !isFinite(g.positions[i])) return false;
    }
    return true;
}

Triangle triangleOf(const ecs::Geometry& g, std::uint32_t t) {
    return Triangle{
        {g.positions[g.indices[3 * t]], g.positions[g.indices[3 * t + 1]], g.positions[g.indices[3 * t + 2]]}};
}

// A leaf slot's data: the triangle's vertices, or a procedural box's corners.
Triangle leafSlotOf(const ecs::Geometry& g, std::uint32_t primitive) {
    if (g.procedural()) return Triangle{{g.proceduralBoxes[primitive].lo, g.proceduralBoxes[primitive].hi, vec3(0.f)}};
    return triangleOf(g, primitive);
}

// Spatial splits of mesh triangles: clip the triangle at the plane and keep
// each side's part inside the reference's current box.
class TriangleSplitter final : public PrimitiveSplitter {
public:
    explicit TriangleSplitter(const ecs::MeshAsset& mesh) : mesh_(mesh) {}
    void split(const PrimitiveRef& ref, const Aabb& bounds, int axis, float position, Aabb& left,
               Aabb& right) const override {
        if (mesh_.geometries[ref.geometry].procedural()) {  // a box: cut it at the plane
            left = bounds;
            right = bounds;
            left.hi[axis] = std::min(left.hi[axis], position);
            right.lo[axis] = std::max(right.lo[axis], position);
            return;
        }
        const Triangle tri = triangleOf(mesh_.geometries[ref.geometry], ref.primitive);
        left = Aabb{};
        right = Aabb{};
        for (int i = 0; i < 3; ++i) {
            const vec3& a = tri.v[i];
            const vec3& b = tri.v[(i + 1) % 3];
            if (a[axis] <= position) left.extend(a);
            if (a[axis] >= position) right.extend(a);
            // The edge crosses the plane: its crossing point belongs to both sides.
            if ((a[axis] < position && b[axis] > position) || (a[axis] > position && b[axis] < position)) {
                const float s = (position - a[axis]) / (b[axis] - a[axis]);
                vec3 p = a + s * (b - a);
                p[axis] = position;
                left.extend(p);
                right.extend(p);
            }
        }
        left = intersectBoxes(left, bounds);
        right = intersectBoxes(right, bounds);
    }

private:
    const ecs::MeshAsset& mesh_;
};

}  // namespace

Aabb BvhNode::bounds() const {
    Aabb b;
    for (std::uint32_t i = 0; i < childCount; ++i) b.extend(childBounds[i]);
    return b;
}

std::uint32_t Bvh::depth() const { return depthOf(*this, root); }

double Bvh::sahCost(float traversalCost, float intersectionCost) const {
    if (empty()) return 0.0;
    const double rootArea = rootBounds.surfaceArea();
    if (!(rootArea > 0.0)) return 0.0;
    double cost = 0.0;
    if (root.isLeaf()) return double(intersectionCost) * leaves[root.index()].refCount;
    for (const BvhNode& node : nodes) {
        cost += double(traversalCost) * node.bounds().surfaceArea();
        for (std::uint32_t i = 0; i < node.childCount; ++i)
            if (node.children[i].isLeaf())
                cost += double(intersectionCost) * node.childBounds[i].surfaceArea() *
                        leaves[node.children[i].index()].refCount;
    }
    return cost / rootArea;
}

Bvh BvhBuilder::build(const std::vector<BuildPrimitive>& primitives, const BuildSettings& settings,
                      const PrimitiveSplitter* splitter) const {
    if (settings.width < 2 || settings.width > kMaxBvhWidth)
        throw std::invalid_argument("BVH width must be in [2, " + std::to_string(kMaxBvhWidth) + "]");
    Bvh bvh;
    bvh.width = settings.width;
    if (primitives.empty()) return bvh;
    for (const BuildPrimitive& p : primitives) bvh.rootBounds.extend(p.bounds);

    // Step: Embree's build primitives; spatial splits need spare capacity.
    const bool spatialSplits = settings.quality == BuildQuality::High && splitter != nullptr;
    std::vector<RTCBuildPrimitive> prims(spatialSplits ? 2 * primitives.size() : primitives.size());
    for (std::size_t i = 0; i < primitives.size(); ++i) {
        const BuildPrimitive& p = primitives[i];
        RTCBuildPrimitive& r = prims[i];
        r.lower_x = p.bounds.lo.x;
        r.lower_y = p.bounds.lo.y;
        r.lower_z = p.bounds.lo.z;
        r.upper_x = p.bounds.hi.x;
        r.upper_y = p.bounds.hi.y;
        r.upper_z = p.bounds.hi.z;
        r.geomID = p.ref.geometry;
        r.primID = p.ref.primitive;
    }

    BuildContext ctx{splitter, spatialSplits};
    RTCBuildArguments args = rtcDefaultBuildArguments();
    args.buildQuality = toRtcQuality(settings.quality);
    args.maxBranchingFactor = settings.width;
    args.maxDepth = kMaxBuildDepth;
    args.minLeafSize = 1;
    args.maxLeafSize = settings.maxLeafSize;
    args.traversalCost = settings.traversalCost;
    args.intersectionCost = settings.intersectionCost;
    args.primitives = prims.data();
    args.primitiveCount = primitives.size();
    args.primitiveArrayCapacity = prims.size();
    args.createNode = createNode;
    args.setNodeChildren = setNodeChildren;
    args.setNodeBounds = setNodeBounds;
    args.createLeaf = createLeaf;
    args.splitPrimitive = spatialSplits ? splitPrimitive : nullptr;
    args.userPtr = &ctx;

    // Step: build on one thread. Embree sizes its parallel partitioning by the
    // arena's concurrency, so a one-thread arena makes the topology independent
    // of the process's thread count (a device "threads=1" would instead cap TBB
    // for the whole process).
    RTCBVH handle = rtcNewBVH(device_);
    if (!handle) throw std::runtime_error("rtcNewBVH failed");
    args.bvh = handle;
    const void* root = nullptr;
    try {
        tbb::task_arena arena(1);
        arena.execute([&] { root = rtcBuildBVH(&args); });
        if (!root) throw std::runtime_error("rtcBuildBVH failed");
        // Step: flatten while Embree's allocator still owns the temporary tree.
        bvh.root = flatten(root, bvh);
    } catch (...) {
        rtcReleaseBVH(handle);
        throw;
    }
    rtcReleaseBVH(handle);
    return bvh;
}

BuildSettings blasBuildSettings(const BvhParams& p) {
    return BuildSettings{p.width, p.maxLeafSize, p.buildQuality, p.sahTraversalCost, p.sahIntersectionCost};
}

BuildSettings tlasBuildSettings(const BvhParams& p) {
    return BuildSettings{p.width, p.tlasMaxLeafSize, p.buildQuality, p.sahTraversalCost, p.sahIntersectionCost};
}

Blas buildBlas(const BvhBuilder& builder, const ecs::MeshAsset& mesh, const BvhParams& params) {
    Blas blas;
    // Step: one build primitive per finite triangle of every triangle geometry.
    std::vector<BuildPrimitive> prims;
    bool deformable = false;
    for (std::uint32_t g = 0; g < mesh.geometries.size(); ++g) {
        const ecs::Geometry& geo = mesh.geometries[g];
        deformable = deformable || geo.deformable();
        if (geo.procedural()) {
            // Procedural geometry: one reference per valid AABB (its box is the build bound).
            blas.triangleCounts.push_back(0);
            blas.proceduralCounts.push_back(static_cast<std::uint32_t>(geo.proceduralBoxes.size()));
            blas.hasProcedural = true;
            for (std::uint32_t b = 0; b < geo.proceduralBoxes.size(); ++b) {
                const Aabb& box = geo.proceduralBoxes[b];
                if (box.empty() || !isFinite(box.lo) || !isFinite(box.hi)) continue;
                prims.push_back(BuildPrimitive{box, PrimitiveRef{g, b}});
            }
            continue;
        }
        blas.triangleCounts.push_back(static_cast<std::uint32_t>(geo.triangleCount()));
        blas.proceduralCounts.push_back(0);
        for (std::uint32_t t = 0; t < geo.triangleCount(); ++t) {
            if (!finiteTriangle(geo, t)) continue;
            const Triangle tri = triangleOf(geo, t);
            BuildPrimitive p;
            for (const vec3& v : tri.v) p.bounds.extend(v);
            p.ref = PrimitiveRef{g, t};
            prims.push_back(p);
        }
    }

    // Step: build; spatial splits only for rigid meshes.
    BuildSettings settings = blasBuildSettings(params);
    if (deformable && settings.quality == BuildQuality::High) settings.quality = BuildQuality::Medium;
    const TriangleSplitter splitter(mesh);
    blas.spatialSplits = settings.quality == BuildQuality::High;
    blas.bvh = builder.build(prims, settings, blas.spatialSplits ? &splitter : nullptr);

    // Step: the leaves' triangle data, in reference order.
    blas.triangles.reserve(blas.bvh.refs.size());
    for (const PrimitiveRef& r : blas.bvh.refs)
        blas.triangles.push_back(leafSlotOf(mesh.geometries[r.geometry], r.primitive));
    blas.buildSahCost = blas.bvh.sahCost(params.sahTraversalCost, params.sahIntersectionCost);
    blas.magnitude = tracer::maxAbsCoordinate(blas.bvh.rootBounds);
    return blas;
}

void refitBlas(Blas& blas, const ecs::MeshAsset& mesh) {
    // Step: the topology must be the one the BVH was built for.
    bool sameTopology = mesh.geometries.size() == blas.triangleCounts.size();
    for (std::size_t g = 0; sameTopology && g < mesh.geometries.size(); ++g) {
        const ecs::Geometry& geo = mesh.geometries[g];
        sameTopology = (geo.procedural() ? 0 : geo.triangleCount()) == blas.triangleCounts[g] &&
                       (geo.procedural() ? geo.proceduralBoxes.size() : 0) == blas.proceduralCounts[g];
    }
    if (!sameTopology)
        throw std::invalid_argument("refitBlas: mesh \"" + mesh.name + "\" changed topology; rebuild it");

    Bvh& bvh = blas.bvh;
    if (bvh.empty()) return;
    // Step: re-read the referenced triangles; leaf boxes from them.
    std::vector<Aabb> leafBounds(bvh.leaves.size());
    for (std::size_t l = 0; l < bvh.leaves.size(); ++l) {
        const BvhLeaf& leaf = bvh.leaves[l];
        for (std::uint32_t i = leaf.firstRef; i < leaf.firstRef + leaf.refCount; ++i) {
            const PrimitiveRef& r = bvh.refs[i];
            blas.triangles[i] = leafSlotOf(mesh.geometries[r.geometry], r.primitive);
            if (blas.isProcedural(r)) leafBounds[l].extend(blas.proceduralBox(i));
            else
                for (const vec3& v : blas.triangles[i].v) leafBounds[l].extend(v);
        }
    }
    // Step: children before parents (pre-order), so walk the nodes backwards.
    for (std::size_t n = bvh.nodes.size(); n-- > 0;) {
        BvhNode& node = bvh.nodes[n];
        for (std::uint32_t i = 0; i < node.childCount; ++i) {
            const NodeRef c = node.children[i];
            node.childBounds[i] = c.isLeaf() ? leafBounds[c.index()] : bvh.nodes[c.index()].bounds();
        }
    }
    bvh.rootBounds = bvh.root.isLeaf() ? leafBounds[bvh.root.index()] : bvh.nodes[bvh.root.index()].bounds();
    blas.magnitude = tracer::maxAbsCoordinate(bvh.rootBounds);
}

}  // namespace rtlab::rtcore_sim
