#pragma once
// The seam between the pipeline (pipeline.hpp) and a traversal back end:
// TraceRay's arguments and results, the counters, the type-erased shader
// table, and the TraversalBackend interface that Embree (embree_backend.hpp)
// and the RT-core model (rtcore_sim/rtcore_backend.hpp) implement.
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/dxr.hpp>

#include <array>
#include <cstdint>
#include <string_view>

namespace rtlab::tracer {

// TraceRay's arguments besides the acceleration structure, ray and payload.
struct TraceArgs {
    std::uint32_t rayFlags = RayFlag::None;
    std::uint32_t instanceInclusionMask = 0xff;
    std::uint32_t rayContribution = 0;  // RayContributionToHitGroupIndex; also the ray type for statistics
    std::uint32_t multiplier = 1;       // MultiplierForGeometryContributionToHitGroupIndex
    std::uint32_t missIndex = 0;
};

// DXR system values visible to hit-group shaders.
struct HitContext {
    vec3 worldRayOrigin{0.f};
    vec3 worldRayDirection{0.f};
    float rayTMin = 0.f;
    float rayTCurrent = 0.f;  // the candidate's t in any-hit, the committed t in closest-hit
    std::uint32_t rayFlags = 0;
    std::uint32_t instanceIndex = 0;  // InstanceIndex(): position in the TLAS
    std::uint32_t instanceId = 0;     // InstanceID(): the instance's user value
    std::uint32_t geometryIndex = 0;
    std::uint32_t primitiveIndex = 0;
    std::uint32_t hitKind = 0;
    std::uint32_t recursionDepth = 0;  // 1 for rays traced by ray generation
    const ecs::InstanceSnapshot* instance = nullptr;

    const mat4& objectToWorld() const { return instance->worldFromObject; }
    mat4 worldToObject() const { return glm::inverse(instance->worldFromObject); }
    vec3 objectRayOrigin() const { return vec3(worldToObject() * vec4(worldRayOrigin, 1.f)); }
    vec3 objectRayDirection() const { return mat3(worldToObject()) * worldRayDirection; }
    vec3 worldHitPosition() const { return worldRayOrigin + rayTCurrent * worldRayDirection; }
};

struct MissContext {
    vec3 worldRayOrigin{0.f};
    vec3 worldRayDirection{0.f};
    float rayTMin = 0.f;
    float rayTCurrent = 0.f;  // TMax
    std::uint32_t rayFlags = 0;
    std::uint32_t recursionDepth = 0;
};

// Intersection shaders see the hit context of the candidate primitive
// (hitKind unused, rayTCurrent = current closest t) and report hits.
class IntersectionContext : public HitContext {
public:
    // ReportHit(): ignored (returns false) unless RayTMin < t < RayTCurrent;
    // otherwise the any-hit shader decides (non-opaque), and an accepted hit
    // shrinks RayTCurrent. hitKind must be < 128 (DXR).
    bool reportHit(float t, std::uint32_t hitKind, const HitAttributes& attributes) const {
        return report_(state_, t, hitKind, attributes);
    }
    using ReportFn = bool (*)(void* state, float t, std::uint32_t hitKind, const HitAttributes& attributes);
    void bind(void* state, ReportFn fn) {
        state_ = state;
        report_ = fn;
    }

private:
    void* state_ = nullptr;
    ReportFn report_ = nullptr;
};

// The hit that traversal committed, if any.
struct CommittedHit {
    bool hit = false;
    float t = kInfinity;
    std::uint32_t instanceIndex = 0;
    std::uint32_t geometryIndex = 0;
    std::uint32_t primitiveIndex = 0;
    std::uint32_t hitKind = 0;
    std::uint32_t hitGroupRecord = 0;
    HitAttributes attributes;
};

// Counters per ray type (RayContributionToHitGroupIndex & 0xf); summed per
// tile and reduced in tile order, so totals are deterministic.
struct TraceCounters {
    static constexpr std::size_t kRayTypes = 16;
    std::array<std::uint64_t, kRayTypes> rays{};
    std::array<std::uint64_t, kRayTypes> hits{};
    std::array<std::uint64_t, kRayTypes> misses{};
    std::uint64_t anyHitInvocations = 0;
    std::uint64_t intersectionInvocations = 0;
    std::uint64_t closestHitInvocations = 0;
    std::uint64_t missInvocations = 0;
    std::uint64_t packetsTraced = 0;
    void add(const TraceCounters& o);
    std::uint64_t totalRays() const;
};

// Type-erased access to the shader table, implemented by Pipeline<Payload>.
class ShaderTableView {
public:
    virtual ~ShaderTableView() = default;
    virtual std::size_t hitGroupCount() const = 0;
    virtual bool anyHitGroupHasAnyHit() const = 0;
    virtual bool hasAnyHit(std::uint32_t record) const = 0;
    virtual AnyHitResult anyHit(std::uint32_t record, const HitContext& ctx, void* payload,
                                const HitAttributes& attributes) const = 0;
    virtual bool hasIntersection(std::uint32_t record) const = 0;
    virtual void intersection(std::uint32_t record, const IntersectionContext& ctx, void* payload) const = 0;
};

class TraceEngine;  // embree_backend.hpp

// The seam between the pipeline and a traversal back end. The pipeline owns
// the shader table and the DXR stages (ray generation, closest-hit, miss);
// a back end finds the committed hit of each ray, calling the shared
// CandidateFilter (candidate_filter.hpp) for every candidate so that ray
// flags, instance flags, any-hit and intersection shaders mean the same on
// every back end. Embree is built in (TraceEngine::trace / trace8, used when
// a Pipeline has no back end set); the RT-core model (rtcore_sim) is the
// other implementation.
class TraversalBackend {
public:
    virtual ~TraversalBackend() = default;
    virtual std::string_view name() const = 0;

    // Traces rays[i] for every i < count with active[i] (one TraceRay each,
    // same arguments, recursion depth `depth`), running any-hit and
    // intersection shaders but not closest-hit/miss; writes out[i] for
    // active lanes and adds to `counters`. Throws what shaders throw and
    // PipelineError for bad records, after the batch.
    virtual void trace(const TraceEngine& engine, const TraceArgs& args, const RayDesc* rays, void* const* payloads,
                       const bool* active, std::size_t count, std::uint32_t depth, CommittedHit* out,
                       TraceCounters& counters) = 0;

    // True when results depend on the order of trace calls (a simulated clock):
    // the pipeline then runs dispatches on the calling thread in tile order,
    // so that results are identical for any thread count.
    virtual bool orderDependent() const = 0;

    // Launches (docs/rtcore-model.md, "Launches"): the trace calls between
    // beginLaunch and endLaunch are one launch of `threads` threads, as one
    // DispatchRays on a GPU; lane i of a call belongs to thread
    // currentTraceScope().thread + i (the pipeline sets it), and a thread's
    // rays depend on each other in the order it traces them. Calls nest: an
    // inner begin/end pair joins the outer launch. abortLaunch drops the
    // launch (a shader threw). Back ends without a clock ignore them.
    // `label` names the launch in statistics (the renderer: the pass).
    virtual void beginLaunch(std::uint32_t threads, std::string_view label) {
        (void)threads;
        (void)label;
    }
    virtual void endLaunch() {}
    virtual void abortLaunch() {}
};

// A launch for the lifetime of the scope: end() ends it (and may throw what
// the back end's simulation throws); leaving the scope without end() (an
// exception) aborts it. No back end: nothing.
class LaunchScope {
public:
    LaunchScope(TraversalBackend* backend, std::uint64_t threads, std::string_view label = "dispatch")
        : backend_(backend) {
        if (threads > UINT32_MAX) throw PipelineError("a launch has at most 2^32 - 1 threads");
        if (backend_) backend_->beginLaunch(static_cast<std::uint32_t>(threads), label);
    }
    ~LaunchScope() {
        if (backend_) backend_->abortLaunch();
    }
    LaunchScope(const LaunchScope&) = delete;
    LaunchScope& operator=(const LaunchScope&) = delete;
    void end() {
        TraversalBackend* b = backend_;
        backend_ = nullptr;
        if (b) b->endLaunch();
    }

private:
    TraversalBackend* backend_;
};

}  // namespace rtlab::tracer
