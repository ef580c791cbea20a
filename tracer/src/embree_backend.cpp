// TraceRay semantics on Embree. Every candidate hit goes through one context
// filter (RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION on every scene) which hands
// it to the shared CandidateFilter (candidate_filter.hpp: the DXR rules and
// the any-hit shader). The instance mask is Embree's ray mask. Procedural
// primitives run the intersection shader from Embree's user geometry
// callbacks; an accepted ReportHit() is committed into Embree's ray/hit.
#include <rtlab/core/simd.hpp>
#include <rtlab/tracer/candidate_filter.hpp>
#include <rtlab/tracer/hit_order.hpp>
#include <rtlab/tracer/instance_transform.hpp>
#include <rtlab/tracer/embree_backend.hpp>
#include <rtlab/tracer/pipeline.hpp>
#include <rtlab/tracer/ray_query.hpp>
#include <rtlab/tracer/watertight_triangle.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <cstring>
#include <exception>

namespace rtlab::tracer {

namespace {

constexpr int kMaxLanes = 8;

// Ray flags whose rules need a per-candidate decision.
constexpr std::uint32_t kCandidateFlags = RayFlag::CullBackFacingTriangles | RayFlag::CullFrontFacingTriangles |
                                          RayFlag::SkipTriangles | RayFlag::CullOpaque | RayFlag::CullNonOpaque |
                                          RayFlag::ForceNonOpaque;

void contextFilter(const RTCFilterFunctionNArguments* args);
// Marks a pipeline trace that runs without a context filter (filterFree):
// Embree never calls it for watertight triangles (user geometry), and the
// callbacks recognise the pipeline context by it.
void filterFreeMarker(const RTCFilterFunctionNArguments*) {}
// Marks a shader-free ray query (ray_query.hpp), likewise never called.
void queryMarker(const RTCFilterFunctionNArguments*) {}

struct PipelineContext;

// The context every rtlab traversal call hands Embree (RTCIntersectContext
// extended; Embree passes it to every callback). It carries the world rays
// of the call, so that watertight triangles see exactly the object-space ray
// every back end computes from the world ray (instance_transform.hpp), as
// the triangle test's 8-lane packet, set up once per instance and not per
// callback. Embree traverses one instance at a time for a whole packet but
// may return to one: the last few instances are kept (direct-mapped by
// index). The lane of a ray is its Embree ray id.
struct TraversalContext {
    RTCIntersectContext embree;           // must stay first
    PipelineContext* pipeline = nullptr;  // the DXR state of a pipeline trace; null for a plain query
    const AccelManager* accel = nullptr;
    alignas(32) float worldOrigin[3][kMaxLanes];
    alignas(32) float worldDirection[3][kMaxLanes];  // zero for lanes without a valid ray

    struct InstanceRays {
        WatertightRayPacket packet;  // not set up for a single ray (see singleRay)
        WatertightRay single;        // lane 0 of a single-ray trace
        std::array<vec3, kMaxLanes> objectDirection;
    };
    // A one-ray trace (rtcIntersect1/rtcOccluded1: callbacks see N == 1 and
    // lane 0 only): its object ray is set up alone, in scalar form, instead
    // of as an 8-lane packet.
    bool singleRay = false;
    static constexpr std::uint32_t kCachedInstances = 8;
    // Which instance each entry holds: the tags in one cache line, so that a
    // context starts (and a lookup hits) without touching the entries.
    std::array<std::uint32_t, kCachedInstances> cachedInstance;
    std::array<InstanceRays, kCachedInstances> instanceRays;

    TraversalContext(const AccelManager& a, RTCFilterFunctionN marker, bool coherent) : accel(&a) {
        rtcInitIntersectContext(&embree);
        cachedInstance.fill(RTC_INVALID_GEOMETRY_ID);
        embree.filter = marker;
        embree.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    }
    // A one-ray trace of `r` (a zero direction where the ray is not valid:
    // the watertight test then never hits). Packets are set by setEmbreePacket.
    void setSingleRay(const RayDesc& r, bool valid) {
        singleRay = true;
        const vec3 d = valid ? r.direction : vec3(0.f);
        const vec3 o = valid ? r.origin : vec3(0.f);
        for (int k = 0; k < 3; ++k) {
            worldOrigin[k][0] = o[k];
            worldDirection[k][0] = d[k];
        }
    }

    InstanceRays& objectRaysFor(std::uint32_t instanceIndex) {
        const std::uint32_t slot = instanceIndex % kCachedInstances;
        InstanceRays& e = instanceRays[slot];
        if (cachedInstance[slot] == instanceIndex) return e;
        cachedInstance[slot] = instanceIndex;
        const glm::dmat4& objectFromWorld = accel->instanceFacts(instanceIndex).objectFromWorld;
        if (singleRay) {
            // The same bits as lane 0 of the packet form (instance_transform.hpp,
            // makeWatertightRay = WatertightRayPacket::setRays per lane).
            const ObjectSpaceRay r =
                toObjectSpace(objectFromWorld, vec3(worldOrigin[0][0], worldOrigin[1][0], worldOrigin[2][0]),
                              vec3(worldDirection[0][0], worldDirection[1][0], worldDirection[2][0]));
            e.objectDirection[0] = r.direction;
            e.single = makeWatertightRay(r.origin, r.direction);
            return e;
        }
        // Lanes without a ray have a zero direction and stay invalid.
        alignas(32) float o[3][kMaxLanes], d[3][kMaxLanes];
        objectSpaceRays8(objectFromWorld, worldOrigin, worldDirection, o, d);
        for (std::uint32_t lane = 0; lane < kMaxLanes; ++lane)
            e.objectDirection[lane] = vec3(d[0][lane], d[1][lane], d[2][lane]);
        e.packet.setRays(o[0], o[1], o[2], d[0], d[1], d[2]);
        return e;
    }
};

// A pipeline trace: the traversal context plus the DXR state of the call.
struct PipelineContext : TraversalContext {
    std::array<LaneCommitState, kMaxLanes> lanes;
    CandidateFilter filter;
    bool occlusion = false;
    // No candidate needs a decision (all geometry opaque triangles, no culling
    // flags): Embree runs without the filter and the committed hit's HitKind
    // and record are computed once, after traversal.
    bool filterFree = false;

    PipelineContext(const TraceEngine& engine, const TraceArgs& args, std::uint32_t depth, TraceCounters& counters,
                    const RayDesc* rays, void* const* payloads, bool coherent)
        : TraversalContext(engine.accel(), contextFilter, coherent),
          filter(engine, args, depth, counters, rays, payloads, lanes.data()) {
        pipeline = this;
        // A shadow-style query (first hit ends the search, no closest-hit) is an
        // occlusion query: Embree stops at the first committed hit.
        occlusion =
            (args.rayFlags & RayFlag::AcceptFirstHitAndEndSearch) && (args.rayFlags & RayFlag::SkipClosestHitShader);
        // ACCEPT_FIRST_HIT on a closest-hit query still needs the filter to stop
        // at the first hit; as an occlusion query Embree stops by itself.
        const bool needsFirstHitStop = (args.rayFlags & RayFlag::AcceptFirstHitAndEndSearch) && !occlusion;
        // Without any-hit shaders a non-opaque candidate is simply accepted, as an
        // opaque one is: opacity then only matters to the CULL_*/FORCE_NON_OPAQUE flags.
        const AccelManager& accel = engine.accel();
        const bool opaqueInEffect = accel.allOpaque() || !engine.shaders().anyHitGroupHasAnyHit();
        filterFree =
            opaqueInEffect && !accel.anyProcedural() && !(args.rayFlags & kCandidateFlags) && !needsFirstHitStop;
        if (filterFree) embree.filter = accel.options().watertight ? filterFreeMarker : nullptr;
    }
};

// The rtlab context behind an Embree context, or null for a foreign one
// (a plain rtcIntersect call on the TLAS).
TraversalContext* traversalContextOf(const RTCIntersectContext* c) {
    if (c && (c->filter == contextFilter || c->filter == filterFreeMarker || c->filter == queryMarker))
        return reinterpret_cast<TraversalContext*>(const_cast<RTCIntersectContext*>(c));
    return nullptr;
}

void contextFilter(const RTCFilterFunctionNArguments* a) {
    PipelineContext& ctx = *traversalContextOf(a->context)->pipeline;
    for (unsigned i = 0; i < a->N; ++i) {
        if (a->valid[i] == 0) continue;
        const std::uint32_t lane = RTCRayN_id(a->ray, a->N, i);
        const bool keep = ctx.filter.triangle(
            lane, RTCRayN_tfar(a->ray, a->N, i), RTCHitN_instID(a->hit, a->N, i, 0), RTCHitN_geomID(a->hit, a->N, i),
            RTCHitN_primID(a->hit, a->N, i),
            vec3(RTCRayN_dir_x(a->ray, a->N, i), RTCRayN_dir_y(a->ray, a->N, i), RTCRayN_dir_z(a->ray, a->N, i)),
            vec3(RTCHitN_Ng_x(a->hit, a->N, i), RTCHitN_Ng_y(a->hit, a->N, i), RTCHitN_Ng_z(a->hit, a->N, i)),
            RTCHitN_u(a->hit, a->N, i), RTCHitN_v(a->hit, a->N, i));
        if (!keep) a->valid[i] = 0;
    }
}

// Embree accepts tnear <= t <= tfar; DXR's interval is open. Both inputs
// are validated non-negative and not NaN, so stepping the bit pattern by one
// is nextafter (towards +inf for the start, towards 0 for the end).
float openIntervalStart(float tMin) {
    if (tMin == kInfinity) return tMin;
    if (tMin == 0.f) return std::numeric_limits<float>::denorm_min();  // also for -0
    return std::bit_cast<float>(std::bit_cast<std::uint32_t>(tMin) + 1u);
}
float openIntervalEnd(float tMax) {
    if (tMax == 0.f) return tMax;  // empty interval either way
    return tMax == kInfinity ? std::numeric_limits<float>::max()
                             : std::bit_cast<float>(std::bit_cast<std::uint32_t>(tMax) - 1u);
}

// An Embree ray for a DXR ray (the open interval made closed, one float
// inwards); the hit starts invalid.
RTCRayHit embreeRay(const RayDesc& r, std::uint32_t mask) {
    RTCRayHit rh{};
    rh.ray.org_x = r.origin.x;
    rh.ray.org_y = r.origin.y;
    rh.ray.org_z = r.origin.z;
    rh.ray.dir_x = r.direction.x;
    rh.ray.dir_y = r.direction.y;
    rh.ray.dir_z = r.direction.z;
    rh.ray.tnear = openIntervalStart(r.tMin);
    rh.ray.tfar = openIntervalEnd(r.tMax);
    rh.ray.mask = mask & 0xff;
    rh.ray.id = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    return rh;
}

// An Embree packet for up to 8 DXR rays (lanes with active[i] false or an
// invalid ray get valid[i] = 0) and the context's world rays; returns
// whether any lane is traced. Validity and the open interval (made closed,
// one float inwards: openIntervalStart/End) 4 lanes per SIMD step.
bool setEmbreePacket(TraversalContext& ctx, const RayDesc* rays, const bool* active, std::uint32_t mask, int* valid,
                     RTCRayHit8& rh) {
    // Step: structure of arrays.
    for (int i = 0; i < kMaxLanes; ++i) {
        const RayDesc& r = rays[i];
        rh.ray.org_x[i] = r.origin.x;
        rh.ray.org_y[i] = r.origin.y;
        rh.ray.org_z[i] = r.origin.z;
        rh.ray.dir_x[i] = r.direction.x;
        rh.ray.dir_y[i] = r.direction.y;
        rh.ray.dir_z[i] = r.direction.z;
        rh.ray.tnear[i] = r.tMin;
        rh.ray.tfar[i] = r.tMax;
        rh.ray.time[i] = 0.f;
        rh.ray.mask[i] = mask & 0xff;
        rh.ray.id[i] = static_cast<unsigned>(i);
        rh.ray.flags[i] = 0;
        rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
        valid[i] = active[i] ? -1 : 0;
    }
    // Step: isValidRay, the interval and the world rays, 4 lanes at a time.
    using VF = simd::vfloat<4>;
    using VI = simd::vint<4>;
    const VF zero = simd::splat<4>(0.f), inf = simd::splat<4>(kInfinity);
    const VF large = simd::splat<4>(kLargestRayCoordinate);
    auto finite = [&](const VF& v) { return (v <= large) & (v >= -large); };  // isValidRay: false for inf and NaN
    std::uint32_t any = 0;
    for (int first = 0; first < kMaxLanes; first += 4) {
        auto at = [&](float* a) { return simd::loadu<4>(a + first); };
        const VF ox = at(rh.ray.org_x), oy = at(rh.ray.org_y), oz = at(rh.ray.org_z);
        const VF dx = at(rh.ray.dir_x), dy = at(rh.ray.dir_y), dz = at(rh.ray.dir_z);
        const VF lo = at(rh.ray.tnear), hi = at(rh.ray.tfar);
        const VI ok = *reinterpret_cast<const VI*>(valid + first) & finite(ox) & finite(oy) & finite(oz) & finite(dx) &
                      finite(dy) & finite(dz) & (lo >= zero) & (hi >= lo);
        *reinterpret_cast<VI*>(valid + first) = ok;
        any |= simd::signMask<4>(ok);
        const VF start = simd::select<4>(
            lo == inf, lo,
            simd::select<4>(lo == zero, simd::splat<4>(std::numeric_limits<float>::denorm_min()), (VF)((VI)lo + 1)));
        const VF end = simd::select<4>(
            hi == zero, hi,
            simd::select<4>(hi == inf, simd::splat<4>(std::numeric_limits<float>::max()), (VF)((VI)hi - 1)));
        simd::storeu<4>(rh.ray.tnear + first, simd::select<4>(ok, start, zero));
        simd::storeu<4>(rh.ray.tfar + first, simd::select<4>(ok, end, zero));
        const VF o[3] = {ox, oy, oz}, d[3] = {dx, dy, dz};
        for (int k = 0; k < 3; ++k) {
            simd::storeu<4>(ctx.worldOrigin[k] + first, simd::select<4>(ok, o[k], zero));
            simd::storeu<4>(ctx.worldDirection[k] + first, simd::select<4>(ok, d[k], zero));
        }
    }
    return any != 0 && ctx.accel->tlas();
}

// Filter-free path: the committed hit straight from Embree's result, with
// its HitKind and record computed once, after traversal. The facing test
// dot(objectDir, Ng) equals dot(worldDir, normalFromObject * Ng).
void commitAfterTraversal(const PipelineContext& ctx, std::uint32_t lane, float t, std::uint32_t instID,
                          std::uint32_t geomID, std::uint32_t primID, const vec3& objectNormal, float u, float v,
                          CommittedHit& out, TraceCounters& counters) {
    const TraceEngine& engine = ctx.filter.engine();
    const InstanceFacts& facts = engine.accel().instanceFacts(instID);
    const vec3& d = ctx.filter.ray(lane).direction;
    float facing;
    if (engine.accel().options().watertight) {
        // The facing test every back end makes (CandidateFilter::triangle): the
        // object-space direction of the shared instance transform against Ng.
        facing = glm::dot(objectSpaceVector(facts.objectFromWorld, d), objectNormal);
    } else {
        // dot(d, N n) = dot(N^T d, n) with N = normalFromObject (column-major mat3).
        const mat3& n = facts.normalFromObject;
        facing = objectNormal.x * glm::dot(n[0], d) + objectNormal.y * glm::dot(n[1], d) +
                 objectNormal.z * glm::dot(n[2], d);
    }
    bool front = facing < 0.f;
    if (facts.frontCounterClockwise) front = !front;
    const std::uint32_t type = ctx.filter.args().rayContribution & 0xf;
    ++counters.rays[type];
    ++counters.hits[type];
    out.hit = true;
    out.t = t;
    out.instanceIndex = instID;
    out.geometryIndex = geomID;
    out.primitiveIndex = primID;
    out.hitKind = front ? kHitKindTriangleFrontFace : kHitKindTriangleBackFace;
    out.hitGroupRecord = engine.hitGroupRecord(ctx.filter.args(), instID, geomID);
    out.attributes = HitAttributes{};
    out.attributes.values[0] = u;
    out.attributes.values[1] = v;
}

RTCRayN* rayOf(const RTCIntersectFunctionNArguments* a) { return RTCRayHitN_RayN(a->rayhit, a->N); }
RTCRayN* rayOf(const RTCOccludedFunctionNArguments* a) { return a->ray; }
RTCHitN* hitOf(const RTCIntersectFunctionNArguments* a) { return RTCRayHitN_HitN(a->rayhit, a->N); }
RTCHitN* hitOf(const RTCOccludedFunctionNArguments*) { return nullptr; }

// Shared body of the intersect and occluded callbacks for procedural primitives.
template <class Args>
void runIntersectionShader(const Args* a, bool occlusion) {
    TraversalContext* traversal = traversalContextOf(a->context);
    if (!traversal || !traversal->pipeline) return;  // non-pipeline traces see no procedural hits
    PipelineContext& ctx = *traversal->pipeline;
    RTCRayN* rayN = rayOf(a);
    const std::uint32_t instanceIndex = a->context->instID[0];
    for (unsigned i = 0; i < a->N; ++i) {
        if (a->valid[i] == 0) continue;
        // An accepted ReportHit() commits into Embree's ray/hit so that
        // traversal shrinks the interval.
        struct Commit {
            const Args* a;
            RTCRayN* rayN;
            unsigned i;
            std::uint32_t lane;
            std::uint32_t instanceIndex;
            bool occlusion;
            const PipelineContext* ctx;
        } commit{a, rayN, i, RTCRayN_id(rayN, a->N, i), instanceIndex, occlusion, &ctx};
        CandidateFilter::ProceduralHooks hooks;
        hooks.state = &commit;
        hooks.currentT = [](void* p) -> float {
            const auto& c = *static_cast<const Commit*>(p);
            // Embree's tfar sits one float below TMax until the first commit (open interval).
            return c.ctx->filter.lane(c.lane).committedAny ? RTCRayN_tfar(c.rayN, c.a->N, c.i)
                                                           : c.ctx->filter.ray(c.lane).tMax;
        };
        hooks.commit = [](void* p, float t) {
            const auto& c = *static_cast<const Commit*>(p);
            if (c.occlusion) {
                RTCRayN_tfar(c.rayN, c.a->N, c.i) = -kInfinity;  // Embree's "occluded"
                return;
            }
            RTCRayN_tfar(c.rayN, c.a->N, c.i) = t;
            RTCHitN* hitN = hitOf(c.a);
            RTCHitN_geomID(hitN, c.a->N, c.i) = c.a->geomID;
            RTCHitN_primID(hitN, c.a->N, c.i) = c.a->primID;
            RTCHitN_instID(hitN, c.a->N, c.i, 0) = c.instanceIndex;
            RTCHitN_u(hitN, c.a->N, c.i) = 0.f;
            RTCHitN_v(hitN, c.a->N, c.i) = 0.f;
            RTCHitN_Ng_x(hitN, c.a->N, c.i) = 0.f;
            RTCHitN_Ng_y(hitN, c.a->N, c.i) = 0.f;
            RTCHitN_Ng_z(hitN, c.a->N, c.i) = 1.f;
        };
        ctx.filter.procedural(commit.lane, instanceIndex, a->geomID, a->primID, hooks);
    }
}

}  // namespace

void proceduralBoundsCallback(const RTCBoundsFunctionArguments* args) {
    storeEmbreeBounds(args->bounds_o, static_cast<const Aabb*>(args->geometryUserPtr)[args->primID]);
}

namespace {

// Watertight triangles (AccelOptions::watertight): one user primitive is a
// cluster of up to kClusterTriangles (4) triangles, tested at once by the Woop-Benthin-Wald test
// (watertight_triangle.hpp). Inside a pipeline trace the object-space ray is
// recomputed from the world ray with the shared instance transform
// (instance_transform.hpp; the same inputs as the RT-core model, so t and
// barycentrics are bit-identical) and candidates go through the DXR filter
// unless the trace is filter-free; plain Embree queries use Embree's object
// ray and commit the nearest hit.
vec3 clusterGeometricNormal(const TriangleCluster& c, std::uint32_t slot) {
    const vec3 p0 = c.vertex(static_cast<int>(slot), 0);
    return glm::cross(c.vertex(static_cast<int>(slot), 1) - p0, c.vertex(static_cast<int>(slot), 2) - p0);
}

// One candidate (slot of the cluster, lane i of the call) against the lane's
// committed hit: the DXR filter (unless filter-free), then the commit.
// Returns true when the lane is finished (an occlusion query found its hit).
template <class Args>
bool considerCandidate(const Args* a, unsigned i, PipelineContext* pipeline, bool occlusion, std::uint32_t lane,
                       std::uint32_t instanceIndex, const TriangleCluster& cluster, std::uint32_t slot, float t,
                       float b1, float b2) {
    float& tfar = RTCRayN_tfar(rayOf(a), a->N, i);
    if (t > tfar) return false;
    RTCHitN* h = hitOf(a);
    const std::uint32_t primitive = cluster.primitive[slot];
    if (!occlusion && t == tfar && RTCHitN_geomID(h, a->N, i) != RTC_INVALID_GEOMETRY_ID &&
        !hitReplaces(t, {instanceIndex, a->geomID, primitive}, tfar,
                     {RTCHitN_instID(h, a->N, i, 0), RTCHitN_geomID(h, a->N, i), RTCHitN_primID(h, a->N, i)}))
        return false;
    if (pipeline && !pipeline->filterFree) {
        const vec3 ng = clusterGeometricNormal(cluster, slot);
        if (!pipeline->filter.triangle(lane, t, instanceIndex, a->geomID, primitive,
                                       pipeline->objectRaysFor(instanceIndex).objectDirection[lane], ng, b1, b2))
            return false;
    }
    if (occlusion) {
        tfar = -kInfinity;  // Embree's "occluded"
        return true;
    }
    tfar = t;
    RTCHitN_u(h, a->N, i) = b1;
    RTCHitN_v(h, a->N, i) = b2;
    const vec3 ng = clusterGeometricNormal(cluster, slot);
    RTCHitN_Ng_x(h, a->N, i) = ng.x;
    RTCHitN_Ng_y(h, a->N, i) = ng.y;
    RTCHitN_Ng_z(h, a->N, i) = ng.z;
    RTCHitN_geomID(h, a->N, i) = a->geomID;
    RTCHitN_primID(h, a->N, i) = primitive;
    RTCHitN_instID(h, a->N, i, 0) = instanceIndex;
    return false;
}

// Embree's interval [tnear, tfar] is inclusive at both ends (rtlab's traces
// moved them one float inwards, making DXR's open interval); the watertight
// test's ends are exclusive, so step one float outwards. At the upper end
// that also lets ties at the committed t reach the id comparison
// (hit_order.hpp), as in the RT-core model.
float exclusiveStart(float tnearInclusive) {
    return tnearInclusive > 0.f ? std::bit_cast<float>(std::bit_cast<std::uint32_t>(tnearInclusive) - 1u)
                                : -std::numeric_limits<float>::denorm_min();
}

// exclusiveStart and tieInclusiveUpperBound for 4 lanes at once (the packet
// callbacks set 8 intervals per call): the same bits as the scalar forms for
// every t Embree hands over (non-negative or NaN tnear; tfar >= 0, +inf or
// NaN; a negative tfar belongs to a finished lane that is never tested).
void setPacketIntervals(const float* tnear, const float* tfar, float* tMin, float* tMax) {
    using VF = simd::vfloat<4>;
    using VI = simd::vint<4>;
    const VF zero = simd::splat<4>(0.f), inf = simd::splat<4>(kInfinity);
    for (int first = 0; first < kMaxLanes; first += 4) {
        const VF lo = simd::loadu<4>(tnear + first), hi = simd::loadu<4>(tfar + first);
        // Step: one float down / up is one step of the bit pattern (GCC vector
        // casts reinterpret the bits).
        const VF loStep = (VF)((VI)lo - 1), hiStep = (VF)((VI)hi + 1);
        const VF start = simd::select<4>(lo > zero, loStep, simd::splat<4>(-std::numeric_limits<float>::denorm_min()));
        const VF end = simd::select<4>((hi >= zero) & (hi < inf), hiStep, hi);
        simd::storeu<4>(tMin + first, start);
        simd::storeu<4>(tMax + first, end);
    }
}

// Set bits of an 8-bit mask (std::popcount is a library call without -mpopcnt).
std::uint32_t laneCount8(std::uint32_t m) {
    m = m - ((m >> 1) & 0x55u);
    m = (m & 0x33u) + ((m >> 2) & 0x33u);
    return (m + (m >> 4)) & 0x0fu;
}

// The valid lanes of an 8-wide callback (bit i for valid[i] != 0) and,
// given the ray ids, whether every valid lane's id is its position.
std::uint32_t packetLanes(const int* valid, const unsigned* ids, bool& lanesInPlace) {
    using VI = simd::vint<4>;
    const VI iota{0, 1, 2, 3}, four = {4, 4, 4, 4}, zero{0, 0, 0, 0};
    const VI v0 = *reinterpret_cast<const VI*>(valid), v1 = *reinterpret_cast<const VI*>(valid + 4);
    const std::uint32_t mask = simd::signMask<4>(v0 != zero) | (simd::signMask<4>(v1 != zero) << 4);
    lanesInPlace = true;
    if (ids) {
        const VI i0 = *reinterpret_cast<const VI*>(ids), i1 = *reinterpret_cast<const VI*>(ids + 4);
        const std::uint32_t inPlace = simd::signMask<4>(i0 == iota) | (simd::signMask<4>(i1 == iota + four) << 4);
        lanesInPlace = (mask & ~inPlace) == 0;
    }
    return mask;
}

// Watertight triangles (AccelOptions::watertight): one user primitive is a
// cluster of up to kClusterTriangles triangles (watertight_triangle.hpp). An
// 8-ray packet is tested one triangle at a time, 8 rays per SIMD step (as
// Embree's own hybrid triangle intersectors); a single ray, or a call with
// fewer rays than the cluster has triangles, against all of them at once. Inside an rtlab trace (pipeline or query) the object-space rays come
// from the context, computed once per instance from the world rays with the
// shared instance transform (instance_transform.hpp; the same inputs as the
// RT-core model, so t and barycentrics are bit-identical), and candidates go
// through the DXR filter unless the trace is filter-free; plain Embree calls
// use Embree's object ray and commit the nearest hit.
template <class Args>
void intersectWatertightCluster(const Args* a, bool occlusion) {
    const auto& mesh = *static_cast<const WatertightTriangles*>(a->geometryUserPtr);
    const TriangleCluster& cluster = mesh.clusters[a->primID];
    RTCRayN* rayN = rayOf(a);
    TraversalContext* traversal = traversalContextOf(a->context);
    PipelineContext* pipeline = traversal ? traversal->pipeline : nullptr;
    const std::uint32_t instanceIndex = a->context->instID[0];
    TraversalContext::InstanceRays* instanceRays = traversal ? &traversal->objectRaysFor(instanceIndex) : nullptr;
    auto laneOf = [&](unsigned i) { return traversal ? RTCRayN_id(rayN, a->N, i) : 0u; };

    // Step: a packet of several rays — 8 rays per SIMD step, one triangle at a
    // time (rtlab's packets keep lane == position, as they are submitted).
    std::uint32_t callMask = 0;  // valid lanes of an 8-wide call
    if (a->N == WatertightRayPacket::kLanes) {
        bool lanesInPlace = true;
        callMask = packetLanes(a->valid, traversal ? &RTCRayN_id(rayN, a->N, 0) : nullptr, lanesInPlace);
        // Fewer rays than triangles: the per-ray form below needs fewer SIMD
        // tests (and a single-ray context has no packet set up).
        const bool packetSetUp = !(traversal && traversal->singleRay);
        if (packetSetUp && laneCount8(callMask) + 1u > cluster.count && (callMask & (callMask - 1u)) != 0 &&
            lanesInPlace) {
            WatertightRayPacket local;
            WatertightRayPacket& packet = instanceRays ? instanceRays->packet : local;
            if (!instanceRays)
                local.setRays(&RTCRayN_org_x(rayN, a->N, 0), &RTCRayN_org_y(rayN, a->N, 0),
                              &RTCRayN_org_z(rayN, a->N, 0), &RTCRayN_dir_x(rayN, a->N, 0),
                              &RTCRayN_dir_y(rayN, a->N, 0), &RTCRayN_dir_z(rayN, a->N, 0));
            setPacketIntervals(&RTCRayN_tnear(rayN, a->N, 0), &RTCRayN_tfar(rayN, a->N, 0), packet.tMin, packet.tMax);
            packet.activate(callMask);
            PacketHits hits;
            if (!intersectPacketWatertight(packet, cluster, hits)) return;
            // Step: the candidates in slot order against each lane's live interval.
            std::uint32_t finished = 0;
            for (std::uint32_t slot = 0; slot < cluster.count; ++slot)
                for (std::uint32_t m = hits.mask[slot] & ~finished; m != 0; m &= m - 1) {
                    const unsigned i = static_cast<unsigned>(std::countr_zero(m));
                    if (considerCandidate(a, i, pipeline, occlusion, i, instanceIndex, cluster, slot, hits.t[slot][i],
                                          hits.b1[slot][i], hits.b2[slot][i]))
                        finished |= 1u << i;
                }
            return;
        }
    }

    // Step: one ray at a time — every triangle of the cluster in one SIMD step.
    ClusterHits hits;
    for (unsigned i = 0; i < a->N; ++i) {
        if (a->N == WatertightRayPacket::kLanes ? !((callMask >> i) & 1u) : a->valid[i] == 0) continue;
        const std::uint32_t lane = laneOf(i);
        const WatertightRay ray =
            instanceRays
                ? (traversal->singleRay ? instanceRays->single : instanceRays->packet.ray(static_cast<int>(lane)))
                : makeWatertightRay(
                      vec3(RTCRayN_org_x(rayN, a->N, i), RTCRayN_org_y(rayN, a->N, i), RTCRayN_org_z(rayN, a->N, i)),
                      vec3(RTCRayN_dir_x(rayN, a->N, i), RTCRayN_dir_y(rayN, a->N, i), RTCRayN_dir_z(rayN, a->N, i)));
        intersectClusterWatertight(ray, cluster, exclusiveStart(RTCRayN_tnear(rayN, a->N, i)),
                                   tieInclusiveUpperBound(RTCRayN_tfar(rayN, a->N, i)), hits);
        for (std::uint32_t m = hits.mask; m != 0; m &= m - 1) {
            const std::uint32_t slot = static_cast<std::uint32_t>(std::countr_zero(m));
            if (considerCandidate(a, i, pipeline, occlusion, lane, instanceIndex, cluster, slot, hits.t[slot],
                                  hits.b1[slot], hits.b2[slot]))
                break;
        }
    }
}

}  // namespace

void watertightIntersectCallback(const RTCIntersectFunctionNArguments* args) {
    intersectWatertightCluster(args, false);
}
void watertightOccludedCallback(const RTCOccludedFunctionNArguments* args) { intersectWatertightCluster(args, true); }

void proceduralIntersectCallback(const RTCIntersectFunctionNArguments* args) { runIntersectionShader(args, false); }
void proceduralOccludedCallback(const RTCOccludedFunctionNArguments* args) { runIntersectionShader(args, true); }

TraceEngine::TraceEngine(const AccelManager& accel, const ShaderTableView& shaders, std::uint32_t rayTypeCount)
    : accel_(accel), shaders_(shaders), rayTypeCount_(rayTypeCount), hitGroupCount_(shaders.hitGroupCount()) {}

void TraceEngine::throwRecordOutOfRange(std::uint64_t record, std::uint32_t instanceIndex,
                                        std::uint32_t geometryIndex) const {
    throw PipelineError("hit group record " + std::to_string(record) + " out of range (table has " +
                        std::to_string(hitGroupCount_) + "; instance " + std::to_string(instanceIndex) + ", geometry " +
                        std::to_string(geometryIndex) + ")");
}

CommittedHit TraceEngine::trace(const TraceArgs& args, const RayDesc& ray, void* payload, std::uint32_t depth,
                                TraceCounters& counters) const {
    CommittedHit out;
    void* payloads[1] = {payload};
    // A single ray is a one-lane trace; no packet overhead for Embree.
    PipelineContext ctx(*this, args, depth, counters, &ray, payloads, false);
    const bool valid = isValidRay(ray);
    ctx.setSingleRay(ray, valid);
    const std::uint32_t type = args.rayContribution & 0xf;
    if (!valid || !accel_.tlas()) {
        // DXR: such rays are undefined; we count them as misses.
        ++counters.rays[type];
        ++counters.misses[type];
        return out;
    }
    RTCRayHit rh = embreeRay(ray, args.instanceInclusionMask);
    if (ctx.occlusion) {
        RTCRay& r = rh.ray;
        rtcOccluded1(accel_.tlas(), &ctx.embree, &r);
        ctx.filter.rethrowIfFailed();
        // Occlusion gives no hit details; the committed filter state does.
        const bool hit = r.tfar < 0.f;
        ctx.filter.finish(0, hit, hit ? ray.tMin : kInfinity, 0, 0, 0, out);
        return out;
    }
    rtcIntersect1(accel_.tlas(), &ctx.embree, &rh);
    ctx.filter.rethrowIfFailed();
    if (ctx.filterFree && rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
        commitAfterTraversal(ctx, 0, rh.ray.tfar, rh.hit.instID[0], rh.hit.geomID, rh.hit.primID,
                             vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z), rh.hit.u, rh.hit.v, out, counters);
        return out;
    }
    ctx.filter.finish(0, rh.hit.geomID != RTC_INVALID_GEOMETRY_ID, rh.ray.tfar, rh.hit.instID[0], rh.hit.geomID,
                      rh.hit.primID, out);
    return out;
}

void TraceEngine::trace8(const TraceArgs& args, const RayDesc* rays, void* const* payloads, const bool* active,
                         std::uint32_t depth, CommittedHit* out, TraceCounters& counters,
                         RayCoherence coherence) const {
    PipelineContext ctx(*this, args, depth, counters, rays, payloads, coherence == RayCoherence::Coherent);
    alignas(32) int valid[kMaxLanes];
    alignas(32) RTCRayHit8 rh;
    const bool any = setEmbreePacket(ctx, rays, active, args.instanceInclusionMask, valid, rh);
    // Step: early-out on an empty mask.
    if (any) {
        ++counters.packetsTraced;
        if (ctx.occlusion) {
            alignas(32) RTCRay8 r{};
            std::memcpy(&r, &rh.ray, sizeof r);
            rtcOccluded8(valid, accel_.tlas(), &ctx.embree, &r);
            ctx.filter.rethrowIfFailed();
            for (int i = 0; i < kMaxLanes; ++i)
                if (active[i]) ctx.filter.finish(i, valid[i] && r.tfar[i] < 0.f, rays[i].tMin, 0, 0, 0, out[i]);
            return;
        }
        rtcIntersect8(valid, accel_.tlas(), &ctx.embree, &rh);
        ctx.filter.rethrowIfFailed();
        if (ctx.filterFree) {
            for (int i = 0; i < kMaxLanes; ++i) {
                if (!active[i]) continue;
                if (valid[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID)
                    commitAfterTraversal(ctx, i, rh.ray.tfar[i], rh.hit.instID[0][i], rh.hit.geomID[i],
                                         rh.hit.primID[i], vec3(rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]),
                                         rh.hit.u[i], rh.hit.v[i], out[i], counters);
                else ctx.filter.finish(i, false, 0.f, 0, 0, 0, out[i]);
            }
            return;
        }
    }
    for (int i = 0; i < kMaxLanes; ++i)
        if (active[i])
            ctx.filter.finish(i, valid[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID, rh.ray.tfar[i],
                              rh.hit.instID[0][i], rh.hit.geomID[i], rh.hit.primID[i], out[i]);
}

// Ray queries (ray_query.hpp): a traversal context without pipeline state;
// the watertight callbacks commit the nearest hit with the tie rule.
namespace {

RTCFilterFunctionN queryMarkerFor(const AccelManager& accel) {
    return accel.options().watertight ? queryMarker : nullptr;
}

QueryHit queryHitOf(const RTCRayHit8& rh, int i) {
    QueryHit h;
    if (rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) return h;
    h.hit = true;
    h.t = rh.ray.tfar[i];
    h.u = rh.hit.u[i];
    h.v = rh.hit.v[i];
    h.instance = rh.hit.instID[0][i];
    h.geometry = rh.hit.geomID[i];
    h.primitive = rh.hit.primID[i];
    return h;
}

}  // namespace

void queryClosest8(const AccelManager& accel, const RayDesc* rays, const bool* active, QueryHit* out,
                   RayCoherence coherence, std::uint32_t instanceMask) {
    TraversalContext ctx(accel, queryMarkerFor(accel), coherence == RayCoherence::Coherent);
    alignas(32) int valid[kMaxLanes];
    alignas(32) RTCRayHit8 rh;
    if (setEmbreePacket(ctx, rays, active, instanceMask, valid, rh))
        rtcIntersect8(valid, accel.tlas(), &ctx.embree, &rh);
    for (int i = 0; i < kMaxLanes; ++i)
        if (active[i]) out[i] = valid[i] ? queryHitOf(rh, i) : QueryHit{};
}

void queryAny8(const AccelManager& accel, const RayDesc* rays, const bool* active, bool* out, RayCoherence coherence,
               std::uint32_t instanceMask) {
    TraversalContext ctx(accel, queryMarkerFor(accel), coherence == RayCoherence::Coherent);
    alignas(32) int valid[kMaxLanes];
    alignas(32) RTCRayHit8 rh;
    if (setEmbreePacket(ctx, rays, active, instanceMask, valid, rh))
        rtcOccluded8(valid, accel.tlas(), &ctx.embree, &rh.ray);
    for (int i = 0; i < kMaxLanes; ++i)
        if (active[i]) out[i] = valid[i] && rh.ray.tfar[i] < 0.f;
}

QueryHit queryClosest(const AccelManager& accel, const RayDesc& ray, std::uint32_t instanceMask) {
    const bool valid = isValidRay(ray);
    if (!valid || !accel.tlas()) return {};
    TraversalContext ctx(accel, queryMarkerFor(accel), false);
    ctx.setSingleRay(ray, valid);
    RTCRayHit rh = embreeRay(ray, instanceMask);
    rtcIntersect1(accel.tlas(), &ctx.embree, &rh);
    QueryHit h;
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return h;
    h.hit = true;
    h.t = rh.ray.tfar;
    h.u = rh.hit.u;
    h.v = rh.hit.v;
    h.instance = rh.hit.instID[0];
    h.geometry = rh.hit.geomID;
    h.primitive = rh.hit.primID;
    return h;
}

bool queryAny(const AccelManager& accel, const RayDesc& ray, std::uint32_t instanceMask) {
    const bool valid = isValidRay(ray);
    if (!valid || !accel.tlas()) return false;
    TraversalContext ctx(accel, queryMarkerFor(accel), false);
    ctx.setSingleRay(ray, valid);
    RTCRayHit rh = embreeRay(ray, instanceMask);
    rtcOccluded1(accel.tlas(), &ctx.embree, &rh.ray);
    return rh.ray.tfar < 0.f;
}

// EmbreeBackend: TraceEngine behind the TraversalBackend interface.
void EmbreeBackend::trace(const TraceEngine& engine, const TraceArgs& args, const RayDesc* rays, void* const* payloads,
                          const bool* active, std::size_t count, std::uint32_t depth, CommittedHit* out,
                          TraceCounters& counters) {
    if (count == 1) {
        if (active[0]) out[0] = engine.trace(args, rays[0], payloads[0], depth, counters);
        return;
    }
    for (std::size_t base = 0; base < count; base += 8) {
        const std::size_t lanes = std::min<std::size_t>(8, count - base);
        if (lanes == 8) {
            engine.trace8(args, rays + base, payloads + base, active + base, depth, out + base, counters, coherence_);
            continue;
        }
        // Step: a partial group padded with inactive lanes.
        std::array<RayDesc, 8> r{};
        std::array<void*, 8> p{};
        std::array<bool, 8> a{};
        std::array<CommittedHit, 8> h{};
        for (std::size_t i = 0; i < lanes; ++i) {
            r[i] = rays[base + i];
            p[i] = payloads[base + i];
            a[i] = active[base + i];
        }
        engine.trace8(args, r.data(), p.data(), a.data(), depth, h.data(), counters, coherence_);
        for (std::size_t i = 0; i < lanes; ++i)
            if (a[i]) out[base + i] = h[i];
    }
}

}  // namespace rtlab::tracer
