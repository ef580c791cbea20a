// The traversal step shared by the functional traversal and the timing model.
#include <rtlab/rtcore_sim/traversal.hpp>
#include <rtlab/tracer/conservative_bounds.hpp>
#include <rtlab/tracer/hit_order.hpp>
#include <rtlab/tracer/instance_transform.hpp>
#include <rtlab/tracer/watertight_triangle.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace rtlab::rtcore_sim {
namespace {

// The slab test, inlined into the traversal step: true with the entry
// distance in tEntry when the box is hit.
inline bool slabTest(const Aabb& box, const vec3& origin, const vec3& invDirection, float tMin, float tMax,
                     float& tEntry, float padding = 0.f) {
    float tNear = tMin;
    float tFar = tMax;
    for (int a = 0; a < 3; ++a) {
        // Near and far planes by the direction's sign: an empty box (lo > hi) gives tNear > tFar.
        // A zero direction component gives +-inf, or NaN when the origin lies
        // exactly on the plane; max/min below ignore NaN (the slab then holds the whole ray).
        const bool negative = std::signbit(invDirection[a]);
        const float nearPlane = negative ? box.hi[a] + padding : box.lo[a] - padding;
        const float farPlane = negative ? box.lo[a] - padding : box.hi[a] + padding;
        const float tA = (nearPlane - origin[a]) * invDirection[a];
        const float tB = (farPlane - origin[a]) * invDirection[a] * kSlabFarScale;
        tNear = tA > tNear ? tA : tNear;
        tFar = tB < tFar ? tB : tFar;
    }
    tEntry = tNear;
    return tNear <= tFar;
}

}  // namespace

vec3 reciprocalDirection(const vec3& direction) { return vec3(1.f) / direction; }

std::optional<float> intersectBox(const Aabb& box, const vec3& origin, const vec3& invDirection, float tMin,
                                  float tMax) {
    float tEntry;
    if (!slabTest(box, origin, invDirection, tMin, tMax, tEntry)) return std::nullopt;
    return tEntry;
}

TraversalCounters& TraversalCounters::operator+=(const TraversalCounters& o) {
    steps += o.steps;
    nodeVisits += o.nodeVisits;
    leafVisits += o.leafVisits;
    boxTests += o.boxTests;
    triangleTests += o.triangleTests;
    proceduralTests += o.proceduralTests;
    instanceTransitions += o.instanceTransitions;
    anyHitCalls += o.anyHitCalls;
    intersectionCalls += o.intersectionCalls;
    maxStackDepth = std::max(maxStackDepth, o.maxStackDepth);
    return *this;
}

// ---------------------------------------------------------------------------
// RayTraversal

void RayTraversal::begin(const ModelScene& scene, const SimRay& ray) {
    scene_ = &scene;
    ray_ = ray;
    tClosest_ = ray.ray.tMax;
    hit_ = ModelHit{};
    counters_ = TraversalCounters{};
    // Padding of TLAS boxes: the instances' magnitudes, and the origin's as
    // an instance transform may amplify the rounding of the object-space ray.
    world_ =
        SpaceRay{ray.ray.origin, ray.ray.direction, reciprocalDirection(ray.ray.direction),
                 tracer::conservativeBoxPadding(
                     scene.tlasMagnitude(), 3.f * scene.tlasConditioning() * tracer::maxAbsCoordinate(ray.ray.origin))};
    object_ = world_;
    blas_ = nullptr;
    instanceIndex_ = 0;
    mesh_ = 0;
    size_ = 0;
    overflow_.clear();
    const Bvh& tlas = scene.tlas();
    finished_ = tlas.empty();
    current_ = StackEntry{tlas.root.bits, ray.ray.tMin, EntryKind::TlasRef};  // the TLAS root box is not tested
}

void RayTraversal::push(const StackEntry& e) {
    if (size_ < stack_.size()) [[likely]] {
        stack_[size_++] = e;
    } else {
        if (size_ == kStackCapacity) throw std::logic_error("rtcore_sim traversal stack overflow");
        overflow_.push_back(e);
        ++size_;
    }
    counters_.maxStackDepth = std::max(counters_.maxStackDepth, static_cast<std::uint32_t>(size_));
}

void RayTraversal::selectNext(StepInfo& info) {
    // The top of the stack, unless a closer hit has been found since it was pushed.
    while (size_ > 0) {
        --size_;
        StackEntry e;
        if (size_ < stack_.size()) [[likely]] {
            e = stack_[size_];
        } else {
            e = overflow_.back();
            overflow_.pop_back();
        }
        ++info.pops;
        if (e.tEntry > tClosest_) continue;
        current_ = e;
        return;
    }
    finished_ = true;
}

void RayTraversal::step(ProgrammableSide& side, std::uint32_t rayIndex, StepInfo& info) {
    info = StepInfo{};
    ++counters_.steps;
    const StackEntry current = current_;

    // Step: instance transition — the ray into the instance's object space.
    if (current.kind == EntryKind::Instance) {
        info.kind = StepKind::Instance;
        info.index = current.refBits;
        instanceIndex_ = current.refBits;
        const ModelInstance& inst = scene_->instances()[instanceIndex_];
        blas_ = scene_->blas(inst.mesh);
        mesh_ = inst.mesh;
        info.mesh = mesh_;
        ++counters_.instanceTransitions;
        const tracer::ObjectSpaceRay objectRay =
            tracer::toObjectSpace(inst.objectFromWorld, world_.origin, world_.direction);
        object_.origin = objectRay.origin;
        object_.direction = objectRay.direction;
        object_.invDirection = reciprocalDirection(object_.direction);
        object_.padding =
            blas_ ? tracer::conservativeBoxPadding(blas_->magnitude, tracer::maxAbsCoordinate(object_.origin)) : 0.f;
        if (!blas_ || blas_->bvh.empty()) return selectNext(info);
        current_ = StackEntry{blas_->bvh.root.bits, current.tEntry, EntryKind::BlasRef};
        return;
    }

    const bool inTlas = current.kind == EntryKind::TlasRef;
    const Bvh& bvh = inTlas ? scene_->tlas() : blas_->bvh;
    const SpaceRay& space = inTlas ? world_ : object_;
    info.tlas = inTlas;
    info.mesh = inTlas ? 0 : mesh_;
    info.index = current.ref().index();

    if (current.ref().isNode()) {
        // Step: internal node — test every child box, visit the nearest next,
        // push the others far-to-near (ties keep slot order).
        info.kind = StepKind::Node;
        ++counters_.nodeVisits;
        const BvhNode& node = bvh.nodes[current.ref().index()];
        std::array<StackEntry, kMaxBvhWidth> hits;  // the first hitCount are written
        std::uint32_t hitCount = 0;
        info.boxTests = node.childCount;
        counters_.boxTests += node.childCount;
        for (std::uint32_t i = 0; i < node.childCount; ++i) {
            float tEntry;
            if (!slabTest(node.childBounds[i], space.origin, space.invDirection, ray_.ray.tMin, tClosest_, tEntry,
                          space.padding))
                continue;
            // Insertion sort by entry distance, nearest first.
            std::uint32_t k = hitCount++;
            while (k > 0 && hits[k - 1].tEntry > tEntry) {
                hits[k] = hits[k - 1];
                --k;
            }
            hits[k] = StackEntry{node.children[i].bits, tEntry, current.kind};
        }
        if (hitCount == 0) return selectNext(info);
        for (std::uint32_t k = hitCount; k-- > 1;) push(hits[k]);
        info.pushes = hitCount - 1;
        current_ = hits[0];
        return;
    }

    ++counters_.leafVisits;
    const BvhLeaf& leaf = bvh.leaves[current.ref().index()];
    if (inTlas) {
        // Step: TLAS leaf — instances passing the mask are entered in
        // reference order (later ones wait on the stack).
        info.kind = StepKind::TlasLeaf;
        std::array<std::uint32_t, 32> entered;
        std::uint32_t enteredCount = 0;
        for (std::uint32_t r = leaf.firstRef; r < leaf.firstRef + leaf.refCount; ++r) {
            const std::uint32_t index = bvh.refs[r].primitive;
            if ((ray_.ray.mask & scene_->instances()[index].mask) != 0) entered[enteredCount++] = index;
        }
        if (enteredCount == 0) return selectNext(info);
        for (std::uint32_t k = enteredCount; k-- > 1;)
            push(StackEntry{entered[k], current.tEntry, EntryKind::Instance});
        info.pushes = enteredCount - 1;
        current_ = StackEntry{entered[0], current.tEntry, EntryKind::Instance};
        return;
    }
    info.kind = StepKind::BlasLeaf;
    blasLeaf(leaf, side, rayIndex, info);
    if (!finished_) selectNext(info);
}

void RayTraversal::blasLeaf(const BvhLeaf& leaf, ProgrammableSide& side, std::uint32_t rayIndex, StepInfo& info) {
    // Step: BLAS leaf — every primitive in reference order; a candidate the
    // side commits becomes the closest hit, later tests use its t.
    const Blas& blas = *blas_;
    for (std::uint32_t r = leaf.firstRef; r < leaf.firstRef + leaf.refCount; ++r) {
        const PrimitiveRef ref = blas.bvh.refs[r];
        if (blas.isProcedural(ref)) {
            if (ray_.skipProcedural) continue;
            ++info.primitiveTests;
            ++counters_.proceduralTests;
            float tEntry;
            if (!slabTest(blas.proceduralBox(r), object_.origin, object_.invDirection, ray_.ray.tMin, tClosest_,
                          tEntry))
                continue;
            const ProceduralVerdict v =
                side.procedural(rayIndex, ProceduralCandidate{instanceIndex_, ref.geometry, ref.primitive, tClosest_});
            if (v.shaderRan) {
                ++info.intersectionCalls;
                ++counters_.intersectionCalls;
            }
            if (v.commit) {
                tClosest_ = v.t;
                hit_ = ModelHit{true, v.t, instanceIndex_, ref.geometry, ref.primitive, 0.f, 0.f, 0.f, true};
            }
            if (v.endSearch) return endSearch();
            continue;
        }
        if (ray_.skipTriangles) continue;
        ++info.primitiveTests;
        ++counters_.triangleTests;
        const Triangle& tri = blas.triangles[r];
        // Ties at the committed t are settled by ids (tracer/hit_order.hpp), as on Embree.
        const std::optional<tracer::TriangleHit> h = tracer::intersectTriangleWatertight(
            object_.origin, object_.direction, tri.v[0], tri.v[1], tri.v[2], ray_.ray.tMin,
            hit_.hit ? tracer::tieInclusiveUpperBound(tClosest_) : tClosest_);
        if (!h) continue;
        if (hit_.hit && !tracer::hitReplaces(h->t, {instanceIndex_, ref.geometry, ref.primitive}, tClosest_,
                                             {hit_.instanceIndex, hit_.geometryIndex, hit_.primitiveIndex}))
            continue;
        TriangleCandidate c;
        c.instance = instanceIndex_;
        c.geometry = ref.geometry;
        c.primitive = ref.primitive;
        c.t = h->t;
        c.u = h->b1;
        c.v = h->b2;
        c.objectDirection = object_.direction;
        c.objectGeometricNormal = glm::cross(tri.v[1] - tri.v[0], tri.v[2] - tri.v[0]);
        const CandidateVerdict v = side.triangle(rayIndex, c);
        if (v.shaderRan) {
            ++info.anyHitCalls;
            ++counters_.anyHitCalls;
        }
        if (v.commit) {
            tClosest_ = h->t;
            hit_ = ModelHit{true,  h->t,  instanceIndex_, ref.geometry, ref.primitive, 1.f - h->b1 - h->b2,
                            h->b1, h->b2, false};
        }
        if (v.endSearch) return endSearch();
    }
}

// ---------------------------------------------------------------------------
// Functional traversal

ModelHit traceRay(const ModelScene& scene, const SimRay& ray, ProgrammableSide& side, std::uint32_t rayIndex,
                  TraversalCounters& counters) {
    RayTraversal traversal;
    traversal.begin(scene, ray);
    StepInfo info;
    while (!traversal.finished()) traversal.step(side, rayIndex, info);
    counters += traversal.counters();
    return traversal.hit();
}

ModelHit traceClosestHit(const ModelScene& scene, const ModelRay& ray, TraversalCounters& counters) {
    OpaqueSide side;
    SimRay simRay;
    simRay.ray = ray;
    return traceRay(scene, simRay, side, 0, counters);
}

}  // namespace rtlab::rtcore_sim
