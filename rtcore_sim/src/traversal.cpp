// Closest-hit traversal of the model's two-level BVH with one stack per ray.
#include <rtlab/rtcore_sim/traversal.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace rtlab::rtcore_sim {
namespace {

constexpr float kMachineEpsilon = std::numeric_limits<float>::epsilon() * 0.5f;
// gamma(n) of pbrt-v4: bound on the relative error of n rounded operations.
constexpr float errorGamma(int n) { return (n * kMachineEpsilon) / (1.f - n * kMachineEpsilon); }

// a*b - c*d with one rounding error (Kahan's algorithm, as pbrt-v4).
float differenceOfProducts(float a, float b, float c, float d) {
    const float cd = c * d;
    const float difference = std::fma(a, b, -cd);
    const float error = std::fma(-c, d, cd);
    return difference + error;
}

int maxComponentIndex(const vec3& v) { return (v.x > v.y) ? (v.x > v.z ? 0 : 2) : (v.y > v.z ? 1 : 2); }
float maxComponent(float a, float b, float c) { return std::max(a, std::max(b, c)); }

// Stack entries: a node or leaf of the TLAS or of the current instance's
// BLAS, or an instance still to enter.
// Trivially constructible, so that the stack array costs nothing to create.
enum class EntryKind : std::uint8_t { TlasRef, BlasRef, Instance };
struct StackEntry {
    std::uint32_t refBits;  // NodeRef bits of a node/leaf; the instance index for Instance
    float tEntry;           // entry distance of its box (culls the entry once a closer hit exists)
    EntryKind kind;
    NodeRef ref() const { return NodeRef{refBits}; }
};

// Bound: (width - 1) entries per level of both trees (each <= 41 levels,
// Embree's depth limit) plus one TLAS leaf's instances.
constexpr std::size_t kStackCapacity = (kMaxBvhWidth - 1) * 2 * 41 + 32 + 1;

class TraversalStack {
public:
    void push(const StackEntry& e, TraversalCounters& counters) {
        if (size_ == entries_.size()) throw std::logic_error("rtcore_sim traversal stack overflow");
        entries_[size_++] = e;
        counters.maxStackDepth = std::max(counters.maxStackDepth, static_cast<std::uint32_t>(size_));
    }
    bool empty() const { return size_ == 0; }
    StackEntry pop() { return entries_[--size_]; }

private:
    std::array<StackEntry, kStackCapacity> entries_;  // left uninitialised: only pushed entries are read
    std::size_t size_ = 0;
};

// The ray in the space of the BVH being traversed.
struct SpaceRay {
    vec3 origin;
    vec3 direction;
    vec3 invDirection;
};

}  // namespace

std::optional<TriangleHit> intersectTriangle(const vec3& origin, const vec3& direction, float tMax, const vec3& p0,
                                             const vec3& p1, const vec3& p2) {
    // Step: degenerate triangles never hit.
    const vec3 n = glm::cross(p2 - p0, p1 - p0);
    if (glm::dot(n, n) == 0.f) return std::nullopt;

    // Step: translate to the ray origin, permute so that z is the direction's largest axis.
    vec3 p0t = p0 - origin, p1t = p1 - origin, p2t = p2 - origin;
    const int kz = maxComponentIndex(glm::abs(direction));
    const int kx = kz == 2 ? 0 : kz + 1;
    const int ky = kx == 2 ? 0 : kx + 1;
    const vec3 d(direction[kx], direction[ky], direction[kz]);
    p0t = vec3(p0t[kx], p0t[ky], p0t[kz]);
    p1t = vec3(p1t[kx], p1t[ky], p1t[kz]);
    p2t = vec3(p2t[kx], p2t[ky], p2t[kz]);

    // Step: shear so that the ray points along +z.
    const float sx = -d.x / d.z;
    const float sy = -d.y / d.z;
    const float sz = 1.f / d.z;
    p0t.x += sx * p0t.z; p0t.y += sy * p0t.z;
    p1t.x += sx * p1t.z; p1t.y += sy * p1t.z;
    p2t.x += sx * p2t.z; p2t.y += sy * p2t.z;

    // Step: edge functions; exactly zero ones are recomputed in double.
    float e0 = differenceOfProducts(p1t.x, p2t.y, p1t.y, p2t.x);
    float e1 = differenceOfProducts(p2t.x, p0t.y, p2t.y, p0t.x);
    float e2 = differenceOfProducts(p0t.x, p1t.y, p0t.y, p1t.x);
    if (e0 == 0.f || e1 == 0.f || e2 == 0.f) {
        e0 = static_cast<float>(double(p1t.x) * double(p2t.y) - double(p1t.y) * double(p2t.x));
        e1 = static_cast<float>(double(p2t.x) * double(p0t.y) - double(p2t.y) * double(p0t.x));
        e2 = static_cast<float>(double(p0t.x) * double(p1t.y) - double(p0t.y) * double(p1t.x));
    }

    // Step: inside when all edge functions have the same sign (zero counts as either).
    if ((e0 < 0.f || e1 < 0.f || e2 < 0.f) && (e0 > 0.f || e1 > 0.f || e2 > 0.f)) return std::nullopt;
    const float det = e0 + e1 + e2;
    if (det == 0.f) return std::nullopt;

    // Step: scaled distance, tested against (0, tMax] without dividing.
    p0t.z *= sz; p1t.z *= sz; p2t.z *= sz;
    const float tScaled = e0 * p0t.z + e1 * p1t.z + e2 * p2t.z;
    if (det < 0.f && (tScaled >= 0.f || tScaled < tMax * det)) return std::nullopt;
    if (det > 0.f && (tScaled <= 0.f || tScaled > tMax * det)) return std::nullopt;

    // Step: barycentrics and t.
    const float invDet = 1.f / det;
    const TriangleHit hit{tScaled * invDet, e0 * invDet, e1 * invDet, e2 * invDet};

    // Step: reject t not conservatively greater than zero (error bounds of pbrt-v4).
    const float maxZt = maxComponent(std::abs(p0t.z), std::abs(p1t.z), std::abs(p2t.z));
    const float deltaZ = errorGamma(3) * maxZt;
    const float maxXt = maxComponent(std::abs(p0t.x), std::abs(p1t.x), std::abs(p2t.x));
    const float maxYt = maxComponent(std::abs(p0t.y), std::abs(p1t.y), std::abs(p2t.y));
    const float deltaX = errorGamma(5) * (maxXt + maxZt);
    const float deltaY = errorGamma(5) * (maxYt + maxZt);
    const float deltaE = 2.f * (errorGamma(2) * maxXt * maxYt + deltaY * maxXt + deltaX * maxYt);
    const float maxE = maxComponent(std::abs(e0), std::abs(e1), std::abs(e2));
    const float deltaT = 3.f * (errorGamma(3) * maxE * maxZt + deltaE * maxZt + deltaZ * maxE) * std::abs(invDet);
    if (hit.t <= deltaT) return std::nullopt;
    return hit;
}

vec3 reciprocalDirection(const vec3& direction) { return vec3(1.f) / direction; }

std::optional<float> intersectBox(const Aabb& box, const vec3& origin, const vec3& invDirection, float tMin, float tMax) {
    constexpr float kFarScale = 1.f + 2.f * errorGamma(3);
    float tNear = tMin;
    float tFar = tMax;
    for (int a = 0; a < 3; ++a) {
        // Near and far planes by the direction's sign: an empty box (lo > hi) gives tNear > tFar.
        // A zero direction component gives +-inf, or NaN when the origin lies
        // exactly on the plane; max/min below ignore NaN (the slab then holds the whole ray).
        const bool negative = std::signbit(invDirection[a]);
        const float nearPlane = negative ? box.hi[a] : box.lo[a];
        const float farPlane = negative ? box.lo[a] : box.hi[a];
        const float tA = (nearPlane - origin[a]) * invDirection[a];
        const float tB = (farPlane - origin[a]) * invDirection[a] * kFarScale;
        tNear = tA > tNear ? tA : tNear;
        tFar = tB < tFar ? tB : tFar;
    }
    if (!(tNear <= tFar)) return std::nullopt;
    return tNear;
}

ModelHit traceClosestHit(const ModelScene& scene, const ModelRay& ray, TraversalCounters& counters) {
    ModelHit hit;
    const Bvh& tlas = scene.tlas();
    if (tlas.empty()) return hit;
    float tClosest = ray.tMax;

    const SpaceRay world{ray.origin, ray.direction, reciprocalDirection(ray.direction)};
    SpaceRay object = world;
    const Blas* blas = nullptr;          // BLAS of the instance being traversed
    std::uint32_t instanceIndex = 0;

    TraversalStack stack;
    StackEntry current{tlas.root.bits, ray.tMin, EntryKind::TlasRef};
    bool haveCurrent = true;
    for (;;) {
        // Step: next entry — the nearest child kept from the last node, else
        // the top of the stack unless a closer hit has been found meanwhile.
        if (!haveCurrent) {
            if (stack.empty()) break;
            current = stack.pop();
            if (current.tEntry > tClosest) continue;
        }
        haveCurrent = false;

        // Step: instance transition — the ray into the instance's object space.
        if (current.kind == EntryKind::Instance) {
            instanceIndex = current.refBits;
            const ModelInstance& inst = scene.instances()[instanceIndex];
            blas = scene.blas(inst.mesh);
            ++counters.instanceTransitions;
            object.origin = vec3(inst.objectFromWorld * glm::dvec4(glm::dvec3(ray.origin), 1.0));
            object.direction = vec3(glm::dmat3(inst.objectFromWorld) * glm::dvec3(ray.direction));
            object.invDirection = reciprocalDirection(object.direction);
            if (!blas || blas->bvh.empty()) continue;
            current = StackEntry{blas->bvh.root.bits, current.tEntry, EntryKind::BlasRef};
            haveCurrent = true;
            continue;
        }

        const bool inTlas = current.kind == EntryKind::TlasRef;
        const Bvh& bvh = inTlas ? tlas : blas->bvh;
        const SpaceRay& space = inTlas ? world : object;

        if (current.ref().isNode()) {
            // Step: internal node — test every child box, visit the nearest
            // next, push the others far-to-near (ties keep slot order).
            ++counters.nodeVisits;
            const BvhNode& node = bvh.nodes[current.ref().index()];
            std::array<StackEntry, kMaxBvhWidth> hits;  // the first hitCount are written
            std::uint32_t hitCount = 0;
            for (std::uint32_t i = 0; i < node.childCount; ++i) {
                ++counters.boxTests;
                const std::optional<float> tEntry =
                    intersectBox(node.childBounds[i], space.origin, space.invDirection, ray.tMin, tClosest);
                if (!tEntry) continue;
                // Insertion sort by entry distance, nearest first.
                std::uint32_t k = hitCount++;
                while (k > 0 && hits[k - 1].tEntry > *tEntry) {
                    hits[k] = hits[k - 1];
                    --k;
                }
                hits[k] = StackEntry{node.children[i].bits, *tEntry, current.kind};
            }
            if (hitCount == 0) continue;
            for (std::uint32_t k = hitCount; k-- > 1;) stack.push(hits[k], counters);
            current = hits[0];
            haveCurrent = true;
            continue;
        }

        // Step: leaf.
        ++counters.leafVisits;
        const BvhLeaf& leaf = bvh.leaves[current.ref().index()];
        if (inTlas) {
            // TLAS leaf: instances passing the mask are entered in reference
            // order (later ones wait on the stack).
            std::array<std::uint32_t, 32> entered;
            std::uint32_t enteredCount = 0;
            for (std::uint32_t r = leaf.firstRef; r < leaf.firstRef + leaf.refCount; ++r) {
                const std::uint32_t index = bvh.refs[r].primitive;
                if ((ray.mask & scene.instances()[index].mask) != 0) entered[enteredCount++] = index;
            }
            if (enteredCount == 0) continue;
            for (std::uint32_t k = enteredCount; k-- > 1;)
                stack.push(StackEntry{entered[k], current.tEntry, EntryKind::Instance}, counters);
            current = StackEntry{entered[0], current.tEntry, EntryKind::Instance};
            haveCurrent = true;
            continue;
        }
        // BLAS leaf: test every triangle; the closest one so far is committed.
        for (std::uint32_t r = leaf.firstRef; r < leaf.firstRef + leaf.refCount; ++r) {
            ++counters.triangleTests;
            const Triangle& tri = blas->triangles[r];
            const std::optional<TriangleHit> h =
                intersectTriangle(object.origin, object.direction, tClosest, tri.v[0], tri.v[1], tri.v[2]);
            if (!h || !(h->t > ray.tMin && h->t < tClosest)) continue;
            tClosest = h->t;
            hit.hit = true;
            hit.t = h->t;
            hit.instanceIndex = instanceIndex;
            hit.geometryIndex = blas->bvh.refs[r].geometry;
            hit.primitiveIndex = blas->bvh.refs[r].primitive;
            hit.b0 = h->b0;
            hit.b1 = h->b1;
            hit.b2 = h->b2;
        }
    }
    return hit;
}

}  // namespace rtlab::rtcore_sim
