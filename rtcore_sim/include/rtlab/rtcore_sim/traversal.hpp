#pragma once
// Traversal of one ray through the model's two-level BVH
// (docs/rtcore-model.md, "Traversal"), written once as a step function
// (RayTraversal::step) that both the functional traversal (traceRay,
// traceClosestHit: steps back to back) and the timing model (RtCore: each
// step charged to the units) run, so that both produce exactly the same hits
// and the same per-ray work counts.
//
// Candidates go to a ProgrammableSide (the DXR any-hit / intersection logic,
// implemented by the tracer adapter); the default OpaqueSide commits every
// triangle candidate and never hits a procedural primitive.
#include <rtlab/core/math.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

namespace rtlab::rtcore_sim {

// The slab test's far-distance scale, 1 + 2 gamma(3) (pbrt-v4's gamma(n):
// a bound on the relative error of n rounded float operations).
inline constexpr float kSlabFarScale = [] {
    constexpr float eps = std::numeric_limits<float>::epsilon() * 0.5f;
    return 1.f + 2.f * ((3 * eps) / (1.f - 3 * eps));
}();

// The reciprocal direction a slab test uses: 1/d per component, +-inf for a
// zero component (the slab test handles it, see intersectBox).
vec3 reciprocalDirection(const vec3& direction);

// Slab test with conservative rounding (the far distance is scaled by
// 1 + 2 gamma(3), pbrt-v4): the entry distance max(tMin, box entry) when
// the ray's [tMin, tMax] overlaps the box, nothing otherwise. Empty boxes
// (lo > hi) are never hit. For a direction component of zero the slab is the
// whole ray when the origin lies within it (also exactly on a face), no
// part of it otherwise.
std::optional<float> intersectBox(const Aabb& box, const vec3& origin, const vec3& invDirection, float tMin,
                                  float tMax);

// A ray with the instance inclusion mask (instance hit when ray.mask &
// instance.mask != 0). Hits are accepted for tMin < t < tMax.
struct ModelRay {
    vec3 origin{0.f};
    float tMin = 0.f;
    vec3 direction{0.f, 0.f, -1.f};
    float tMax = kInfinity;
    std::uint8_t mask = 0xff;
};

struct ModelHit {
    bool hit = false;
    float t = kInfinity;
    std::uint32_t instanceIndex = 0;   // position in ModelScene::instances() (= Embree instID)
    std::uint32_t geometryIndex = 0;   // geometry of the instance's mesh (= Embree geomID)
    std::uint32_t primitiveIndex = 0;  // triangle (or AABB) of that geometry (= Embree primID)
    // Triangle hits: barycentrics, DXR/Embree (u, v) = (b1, b2), b0 = 1 - b1 - b2
    // (all zero for a procedural hit).
    float b0 = 0.f, b1 = 0.f, b2 = 0.f;
    bool procedural = false;  // committed by an intersection shader
};

// Work one ray did, summed over both levels.
struct TraversalCounters {
    std::uint32_t steps = 0;                // traversal steps (node, leaf and instance steps)
    std::uint32_t nodeVisits = 0;           // internal nodes whose child boxes were tested
    std::uint32_t leafVisits = 0;           // leaves processed (TLAS instance leaves and BLAS primitive leaves)
    std::uint32_t boxTests = 0;             // child AABBs tested (= sum of childCount over node visits)
    std::uint32_t triangleTests = 0;        // ray/triangle tests
    std::uint32_t proceduralTests = 0;      // ray/AABB tests of procedural leaf references
    std::uint32_t instanceTransitions = 0;  // world->object ray transforms (instances entered after the mask test)
    std::uint32_t anyHitCalls = 0;          // triangle candidates whose verdict ran a shader
    std::uint32_t intersectionCalls = 0;    // procedural candidates whose verdict ran a shader
    std::uint32_t maxStackDepth = 0;        // most entries held on the traversal stack at once

    // Sums the counts; maxStackDepth becomes the larger of the two.
    TraversalCounters& operator+=(const TraversalCounters& o);
};

// ---------------------------------------------------------------------------
// The programmable side.

// A triangle hit with tMin < t < tClosest, before it is committed.
struct TriangleCandidate {
    std::uint32_t instance = 0, geometry = 0, primitive = 0;
    float t = 0.f, u = 0.f, v = 0.f;
    vec3 objectDirection{0.f};        // the ray direction in object space (facing)
    vec3 objectGeometricNormal{0.f};  // (p1 - p0) x (p2 - p0), object space
};
struct CandidateVerdict {
    bool commit = true;      // the candidate becomes the closest hit (tClosest = its t)
    bool endSearch = false;  // stop traversing this ray (after the commit)
    bool shaderRan = false;  // an any-hit shader ran: one programmable round trip is charged
};
// A procedural AABB the ray overlaps within [tMin, tClosest].
struct ProceduralCandidate {
    std::uint32_t instance = 0, geometry = 0, primitive = 0;
    float tClosest = 0.f;  // the current closest t (tMax before any commit)
};
struct ProceduralVerdict {
    bool commit = false;  // the intersection shader committed a hit at t (the side checked the interval)
    float t = 0.f;
    bool endSearch = false;
    bool shaderRan = false;  // an intersection shader ran: one programmable round trip is charged
};

class ProgrammableSide {
public:
    virtual ~ProgrammableSide() = default;
    // Called when the triangle unit finds tMin < t < tClosest for `rayIndex`
    // (index into the submitted batch; 0 for the functional traceRay).
    virtual CandidateVerdict triangle(std::uint32_t rayIndex, const TriangleCandidate& c) = 0;
    virtual ProceduralVerdict procedural(std::uint32_t rayIndex, const ProceduralCandidate& c) = 0;
    // True when callbacks for different rays may run at the same time on
    // several host threads, in any interleaving: a verdict depends only on
    // that ray's own candidates and a call touches no state shared with
    // other rays' calls. The GPU model (RtCore with gpu.cores > 1) then
    // advances its cores on several host threads (docs/rtcore-model.md,
    // "Host threads"); otherwise it runs them on the calling thread, cycle
    // by cycle. Cycles and statistics are the same either way.
    virtual bool concurrent() const { return false; }
};

// Opaque triangles, every candidate committed, no shaders; procedural never hit.
class OpaqueSide final : public ProgrammableSide {
public:
    CandidateVerdict triangle(std::uint32_t, const TriangleCandidate&) override { return {}; }
    ProceduralVerdict procedural(std::uint32_t, const ProceduralCandidate&) override { return {}; }
    bool concurrent() const override { return true; }
};

// A ray as submitted to the RT core. skipTriangles / skipProcedural leave
// those primitives untested (DXR SKIP_TRIANGLES / SKIP_PROCEDURAL_PRIMITIVES).
struct SimRay {
    ModelRay ray;
    std::uint32_t rayType = 0;  // for statistics (DXR ray contribution, e.g. 0 = radiance, 1 = shadow)
    bool skipTriangles = false;
    bool skipProcedural = false;
};

// ---------------------------------------------------------------------------
// The shared step function.

// Stack entries: a node or leaf of the TLAS or of the current instance's
// BLAS, or an instance still to enter. Trivially constructible, so that the
// stack array costs nothing to create.
enum class EntryKind : std::uint8_t { TlasRef, BlasRef, Instance };
struct StackEntry {
    std::uint32_t refBits;  // NodeRef bits of a node/leaf; the instance index for Instance
    float tEntry;           // entry distance of its box (culls the entry once a closer hit exists)
    EntryKind kind;
    NodeRef ref() const { return NodeRef{refBits}; }
};

// What one step processed, for the timing model.
enum class StepKind : std::uint8_t { Node, TlasLeaf, BlasLeaf, Instance };
struct StepInfo {
    StepKind kind = StepKind::Node;
    bool tlas = false;                 // a TLAS node or leaf
    std::uint32_t mesh = 0;            // BLAS steps: the mesh whose BLAS was traversed
    std::uint32_t index = 0;           // node index, leaf index, or instance index
    std::uint32_t boxTests = 0;        // Node: child boxes tested
    std::uint32_t primitiveTests = 0;  // BlasLeaf: triangle + procedural AABB tests
    std::uint32_t anyHitCalls = 0;     // shader round trips of this step
    std::uint32_t intersectionCalls = 0;
    std::uint32_t pushes = 0;  // stack entries pushed (before the pops)
    std::uint32_t pops = 0;    // stack entries popped when choosing the next entry (including culled ones)
};

// Bound: (width - 1) entries per level of both trees (each <= 41 levels,
// Embree's depth limit) plus one TLAS leaf's instances.
inline constexpr std::size_t kStackCapacity = (kMaxBvhWidth - 1) * 2 * 41 + 32 + 1;
// Entries held in the traversal object itself; deeper ones go to a heap
// overflow (rare), so that a ray in flight is under a kilobyte (the timing
// model keeps thousands of them: their headers stay within few host pages).
inline constexpr std::size_t kInlineStackEntries = 32;

// One ray in flight. A step processes the current entry:
//   Node      test every child box; visit the nearest hit child next, push
//             the others far-to-near
//   TlasLeaf  instances passing the mask: the first is next, the others pushed
//   Instance  transform the ray into object space; the BLAS root is next
//   BlasLeaf  test every primitive (triangles watertight, procedural AABBs
//             by the slab test), candidates to the ProgrammableSide
// and then, when no child was chosen, pops the stack until an entry whose
// tEntry <= tClosest (or the stack is empty: the ray is finished).
class RayTraversal {
public:
    // Starts `ray`; finished() right away when the scene is empty.
    void begin(const ModelScene& scene, const SimRay& ray);
    bool finished() const { return finished_; }
    // Processes the current entry and selects the next one. Only when !finished().
    void step(ProgrammableSide& side, std::uint32_t rayIndex, StepInfo& info);

    // The entry the next step processes (when !finished()) and, for a
    // BlasRef entry, the mesh of the instance being traversed.
    const StackEntry& next() const { return current_; }
    // Where next() and finished() live (a host prefetch hint for the timing model).
    const void* nextEntryAddress() const { return &current_; }
    std::uint32_t currentMesh() const { return mesh_; }
    const ModelHit& hit() const { return hit_; }
    const TraversalCounters& counters() const { return counters_; }

private:
    void push(const StackEntry& e);
    void selectNext(StepInfo& info);  // pops until a live entry; sets finished_ when none is left
    void endSearch() {
        size_ = 0;
        finished_ = true;
    }
    void blasLeaf(const BvhLeaf& leaf, ProgrammableSide& side, std::uint32_t rayIndex, StepInfo& info);

    struct SpaceRay {
        vec3 origin;
        vec3 direction;
        vec3 invDirection;
        // Node boxes are enlarged by this much for this ray, so that the box
        // test is conservative at the magnitude of the boxes and the origin
        // (tracer/conservative_bounds.hpp).
        float padding = 0.f;
    };

    const ModelScene* scene_ = nullptr;
    SimRay ray_;
    float tClosest_ = 0.f;
    ModelHit hit_;
    TraversalCounters counters_;
    SpaceRay world_{}, object_{};
    const Blas* blas_ = nullptr;  // BLAS of the instance being traversed
    std::uint32_t instanceIndex_ = 0;
    std::uint32_t mesh_ = 0;
    StackEntry current_{};
    bool finished_ = true;
    std::size_t size_ = 0;
    std::array<StackEntry, kInlineStackEntries>
        stack_;                         // the bottom entries; left uninitialised: only pushed ones are read
    std::vector<StackEntry> overflow_;  // entries beyond kInlineStackEntries (up to kStackCapacity)
};

// Functional traversal: the steps of `ray` back to back, candidates to `side`;
// the ray's work is added to `counters`.
ModelHit traceRay(const ModelScene& scene, const SimRay& ray, ProgrammableSide& side, std::uint32_t rayIndex,
                  TraversalCounters& counters);

// Closest hit of `ray` (world space) in `scene`: OpaqueSide (every triangle
// candidate committed, procedural primitives never hit); work added to `counters`.
ModelHit traceClosestHit(const ModelScene& scene, const ModelRay& ray, TraversalCounters& counters);

}  // namespace rtlab::rtcore_sim
