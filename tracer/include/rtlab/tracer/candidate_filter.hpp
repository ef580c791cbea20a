#pragma once
// The DXR decision for candidate hits, shared by every traversal back end
// (Embree's filter callbacks, the RT-core model's triangle unit). For one
// trace call over N rays ("lanes") it applies, in DXR order: the open
// (TMin, TMax) interval, SKIP_TRIANGLES / SKIP_PROCEDURAL_PRIMITIVES, face
// culling (with instance flags), opacity (geometry flag, instance and ray
// overrides), CULL_OPAQUE / CULL_NON_OPAQUE, the any-hit shader for
// non-opaque candidates, and ACCEPT_FIRST_HIT_AND_END_SEARCH; procedural
// primitives run their intersection shader, whose ReportHit() goes through
// the same rules. A back end owns traversal and the current closest t; the
// filter owns what DXR commits (HitKind, record, attributes) per lane.
#include <rtlab/tracer/pipeline.hpp>

#include <array>
#include <cstdint>
#include <exception>

namespace rtlab::tracer {

// What a trace call has committed for one ray so far.
struct LaneCommitState {
    bool ended = false;         // the search is over (AcceptHitAndEndSearch / ACCEPT_FIRST_HIT_AND_END_SEARCH)
    bool committedAny = false;  // RayTCurrent is TMax until the first commit
    std::uint32_t hitKind = 0;
    std::uint32_t record = 0;
    std::array<float, 8> attributes;  // valid once committedAny (left uninitialised until then)
};

class CandidateFilter {
public:
    // `rays`, `payloads` and `lanes` are indexed by lane and must outlive the filter.
    CandidateFilter(const TraceEngine& engine, const TraceArgs& args, std::uint32_t depth, TraceCounters& counters,
                    const RayDesc* rays, void* const* payloads, LaneCommitState* lanes)
        : engine_(&engine), args_(args), depth_(depth), counters_(&counters), rays_(rays), payloads_(payloads),
          lanes_(lanes) {}

    // A triangle candidate at t: true when committed (the back end then makes t
    // its closest distance). objectDirection and objectGeometricNormal
    // ((p1-p0)x(p2-p0)) decide the facing; u, v are the barycentrics.
    bool triangle(std::uint32_t lane, float t, std::uint32_t instance, std::uint32_t geometry, std::uint32_t primitive,
                  const vec3& objectDirection, const vec3& objectGeometricNormal, float u, float v);

    // How the intersection shader's ReportHit reaches the back end: the
    // current closest t (RayTCurrent; TMax before the first commit is the
    // back end's business) and a commit of an accepted hit at t.
    struct ProceduralHooks {
        void* state = nullptr;
        float (*currentT)(void* state) = nullptr;
        void (*commit)(void* state, float t) = nullptr;
    };
    // A procedural primitive reached by traversal: unless skipped or culled by
    // opacity, runs its intersection shader. Returns whether the shader ran.
    bool procedural(std::uint32_t lane, std::uint32_t instance, std::uint32_t geometry, std::uint32_t primitive,
                    const ProceduralHooks& hooks);

    bool ended(std::uint32_t lane) const { return lanes_[lane].ended; }
    const LaneCommitState& lane(std::uint32_t lane) const { return lanes_[lane]; }
    // The first exception thrown by a shader or raised by a bad record; the
    // filter rejects everything after it. Back ends rethrow after traversal.
    bool failed() const { return static_cast<bool>(error_); }
    void rethrowIfFailed() const {
        if (error_) std::rethrow_exception(error_);
    }

    // After traversal: the lane's result and its counters. For a hit, t and
    // the ids come from the back end, HitKind/record/attributes from the
    // filter's commit state.
    void finish(std::uint32_t lane, bool hit, float t, std::uint32_t instance, std::uint32_t geometry,
                std::uint32_t primitive, CommittedHit& out) const;

    const TraceArgs& args() const { return args_; }
    const TraceEngine& engine() const { return *engine_; }
    const RayDesc& ray(std::uint32_t lane) const { return rays_[lane]; }
    TraceCounters& counters() const { return *counters_; }

private:
    // Interval, opacity, any-hit and commit: the part triangles and
    // procedural reports share.
    bool decide(std::uint32_t lane, float t, std::uint32_t instance, std::uint32_t geometry, std::uint32_t primitive,
                std::uint32_t hitKind, const HitAttributes& attributes);

    const TraceEngine* engine_;
    TraceArgs args_;
    std::uint32_t depth_;
    TraceCounters* counters_;
    const RayDesc* rays_;
    void* const* payloads_;
    LaneCommitState* lanes_;
    std::exception_ptr error_;
};

// DXR: a procedural primitive is culled by opacity before its intersection
// shader runs; opacity = geometry flag, then instance, then ray overrides.
bool isOpaque(const GeometryInfo& geometry, const ecs::InstanceSnapshot& instance, std::uint32_t rayFlags);
bool culledByOpacity(bool opaque, std::uint32_t rayFlags);

}  // namespace rtlab::tracer
