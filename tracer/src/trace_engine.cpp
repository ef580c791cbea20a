// TraceRay semantics on Embree. Every candidate hit goes through one context
// filter (RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION on every scene) which applies,
// in DXR order: the open (TMin, TMax) interval, SKIP_TRIANGLES, face culling
// (with instance flags), opacity (geometry flag, instance and ray overrides),
// CULL_OPAQUE / CULL_NON_OPAQUE, then the any-hit shader for non-opaque hits,
// and ACCEPT_FIRST_HIT_AND_END_SEARCH. The instance mask is Embree's ray mask.
// Procedural primitives call the intersection shader from Embree's user
// geometry callbacks; ReportHit() runs the same filter via rtcFilterIntersection.
#include <rtlab/tracer/pipeline.hpp>
#include <rtlab/tracer/watertight_triangle.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <cstring>
#include <exception>

namespace rtlab::tracer {

void TraceCounters::add(const TraceCounters& o) {
    for (std::size_t i = 0; i < kRayTypes; ++i) {
        rays[i] += o.rays[i];
        hits[i] += o.hits[i];
        misses[i] += o.misses[i];
    }
    anyHitInvocations += o.anyHitInvocations;
    intersectionInvocations += o.intersectionInvocations;
    closestHitInvocations += o.closestHitInvocations;
    missInvocations += o.missInvocations;
    packetsTraced += o.packetsTraced;
}

std::uint64_t TraceCounters::totalRays() const {
    std::uint64_t n = 0;
    for (std::uint64_t r : rays) n += r;
    return n;
}

TraceScope& currentTraceScope() {
    thread_local TraceScope scope;
    return scope;
}

namespace {

constexpr int kMaxLanes = 8;

// RTCIntersectContext extended with the state of one trace call. Embree
// hands the context to every callback; the lane is recovered from ray.id.
struct PipelineContext {
    RTCIntersectContext embree;  // must stay first
    const TraceEngine* engine = nullptr;
    TraceArgs args;
    std::uint32_t depth = 0;
    bool occlusion = false;
    TraceCounters* counters = nullptr;
    const RayDesc* rays = nullptr;     // world-space rays, per lane
    void* const* payloads = nullptr;   // per lane
    std::array<bool, kMaxLanes> ended{};
    // Written on commit, read only for committed lanes: plain floats so that
    // the context is not zero-filled per trace.
    std::array<std::array<float, 8>, kMaxLanes> committedAttributes;
    std::array<std::uint32_t, kMaxLanes> committedHitKind{};
    std::array<std::uint32_t, kMaxLanes> committedRecord{};
    std::array<bool, kMaxLanes> committedAny{};  // RayTCurrent is TMax until the first commit
    // Set by ReportHit() for the procedural candidate being filtered.
    std::uint32_t pendingHitKind = 0;
    HitAttributes pendingAttributes;
    std::exception_ptr error;  // first exception from a shader or a bad record
    // No candidate needs a decision (all geometry opaque triangles, no culling
    // flags): Embree runs without the filter and the committed hit's HitKind
    // and record are computed once, after traversal.
    bool filterFree = false;
};

// Ray flags whose rules need a per-candidate decision.
constexpr std::uint32_t kCandidateFlags = RayFlag::CullBackFacingTriangles | RayFlag::CullFrontFacingTriangles |
                                          RayFlag::SkipTriangles | RayFlag::CullOpaque | RayFlag::CullNonOpaque |
                                          RayFlag::ForceNonOpaque;

void contextFilter(const RTCFilterFunctionNArguments* args);

bool isPipelineContext(const RTCIntersectContext* c) { return c && c->filter == contextFilter; }

// Opacity: geometry flag, then instance overrides, then ray overrides.
bool isOpaque(const GeometryInfo& geo, const ecs::InstanceSnapshot& inst, std::uint32_t rayFlags) {
    bool opaque = geo.opaque;
    if (inst.flags & InstanceFlag::ForceOpaque) opaque = true;
    if (inst.flags & InstanceFlag::ForceNonOpaque) opaque = false;
    if (rayFlags & RayFlag::ForceOpaque) opaque = true;
    if (rayFlags & RayFlag::ForceNonOpaque) opaque = false;
    return opaque;
}

bool culledByOpacity(bool opaque, std::uint32_t rayFlags) {
    return opaque ? (rayFlags & RayFlag::CullOpaque) != 0 : (rayFlags & RayFlag::CullNonOpaque) != 0;
}

// The DXR decision for one candidate hit; returns true when committed.
bool filterCandidate(PipelineContext& ctx, std::uint32_t lane, float t, std::uint32_t instanceIndex,
                     std::uint32_t geometryIndex, std::uint32_t primitiveIndex, const vec3& objectDirection,
                     const vec3& geometricNormal, float u, float v) {
    if (ctx.ended[lane] || ctx.error) return false;
    const RayDesc& ray = ctx.rays[lane];
    // Step: the ray is the open interval (TMin, TMax).
    if (!(t > ray.tMin && t < ray.tMax)) return false;
    const AccelManager& accel = ctx.engine->accel();
    const ecs::InstanceSnapshot& inst = accel.instance(instanceIndex);
    const GeometryInfo& geo = accel.geometryInfo(inst.mesh, geometryIndex);
    const std::uint32_t flags = ctx.args.rayFlags;

    std::uint32_t hitKind = 0;
    if (!geo.procedural) {
        // Step: triangles — skipping and face culling.
        if (flags & RayFlag::SkipTriangles) return false;
        // DXR: front face = clockwise seen from the ray origin in a left-handed
        // frame, i.e. dot(direction, (v1-v0)x(v2-v0)) < 0 numerically.
        bool front = glm::dot(objectDirection, geometricNormal) < 0.f;
        if (inst.flags & InstanceFlag::TriangleFrontCounterClockwise) front = !front;
        hitKind = front ? kHitKindTriangleFrontFace : kHitKindTriangleBackFace;
        if (!(inst.flags & InstanceFlag::TriangleCullDisable)) {
            if ((flags & RayFlag::CullBackFacingTriangles) && !front) return false;
            if ((flags & RayFlag::CullFrontFacingTriangles) && front) return false;
        }
    } else {
        if (flags & RayFlag::SkipProceduralPrimitives) return false;
        hitKind = ctx.pendingHitKind;
    }

    // Step: opacity — geometry flag, then instance overrides, then ray overrides.
    const bool opaque = isOpaque(geo, inst, flags);
    if (culledByOpacity(opaque, flags)) return false;

    std::uint32_t record = 0;
    try {
        record = ctx.engine->hitGroupRecord(ctx.args, instanceIndex, geometryIndex);
    } catch (...) {
        ctx.error = std::current_exception();
        return false;
    }
    HitAttributes attributes;
    if (geo.procedural) {
        attributes = ctx.pendingAttributes;
    } else {
        attributes.values[0] = u;
        attributes.values[1] = v;
    }

    // Step: any-hit for non-opaque candidates.
    bool endSearch = (flags & RayFlag::AcceptFirstHitAndEndSearch) != 0;
    const ShaderTableView& shaders = ctx.engine->shaders();
    if (!opaque && shaders.hasAnyHit(record)) {
        ++ctx.counters->anyHitInvocations;
        HitContext hc;
        hc.worldRayOrigin = ray.origin;
        hc.worldRayDirection = ray.direction;
        hc.rayTMin = ray.tMin;
        hc.rayTCurrent = t;
        hc.rayFlags = flags;
        hc.instanceIndex = instanceIndex;
        hc.instanceId = inst.instanceId;
        hc.geometryIndex = geometryIndex;
        hc.primitiveIndex = primitiveIndex;
        hc.hitKind = hitKind;
        hc.recursionDepth = ctx.depth;
        hc.instance = &inst;
        AnyHitResult result = AnyHitResult::Ignore;
        try {
            result = shaders.anyHit(record, hc, ctx.payloads[lane], attributes);
        } catch (...) {
            ctx.error = std::current_exception();
            return false;
        }
        if (result == AnyHitResult::Ignore) return false;
        if (result == AnyHitResult::AcceptAndEndSearch) endSearch = true;
    }

    // Step: commit.
    ctx.committedAttributes[lane] = attributes.values;
    ctx.committedHitKind[lane] = hitKind;
    ctx.committedRecord[lane] = record;
    ctx.committedAny[lane] = true;
    if (endSearch) ctx.ended[lane] = true;
    return true;
}

void contextFilter(const RTCFilterFunctionNArguments* a) {
    auto& ctx = *reinterpret_cast<PipelineContext*>(a->context);
    for (unsigned i = 0; i < a->N; ++i) {
        if (a->valid[i] == 0) continue;
        const std::uint32_t lane = RTCRayN_id(a->ray, a->N, i);
        const bool keep = filterCandidate(
            ctx, lane, RTCRayN_tfar(a->ray, a->N, i), RTCHitN_instID(a->hit, a->N, i, 0), RTCHitN_geomID(a->hit, a->N, i),
            RTCHitN_primID(a->hit, a->N, i),
            vec3(RTCRayN_dir_x(a->ray, a->N, i), RTCRayN_dir_y(a->ray, a->N, i), RTCRayN_dir_z(a->ray, a->N, i)),
            vec3(RTCHitN_Ng_x(a->hit, a->N, i), RTCHitN_Ng_y(a->hit, a->N, i), RTCHitN_Ng_z(a->hit, a->N, i)),
            RTCHitN_u(a->hit, a->N, i), RTCHitN_v(a->hit, a->N, i));
        if (!keep) a->valid[i] = 0;
    }
}

void initContext(PipelineContext& ctx, const TraceEngine* engine, const TraceArgs& args, std::uint32_t depth,
                 TraceCounters& counters, const RayDesc* rays, void* const* payloads, bool coherent) {
    rtcInitIntersectContext(&ctx.embree);
    ctx.embree.filter = contextFilter;
    ctx.embree.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    ctx.engine = engine;
    ctx.args = args;
    ctx.depth = depth;
    ctx.counters = &counters;
    ctx.rays = rays;
    ctx.payloads = payloads;
    // A shadow-style query (first hit ends the search, no closest-hit) is an
    // occlusion query: Embree stops at the first committed hit.
    ctx.occlusion = (args.rayFlags & RayFlag::AcceptFirstHitAndEndSearch) &&
                    (args.rayFlags & RayFlag::SkipClosestHitShader);
    // ACCEPT_FIRST_HIT on a closest-hit query still needs the filter to stop
    // at the first hit; as an occlusion query Embree stops by itself.
    const bool needsFirstHitStop = (args.rayFlags & RayFlag::AcceptFirstHitAndEndSearch) && !ctx.occlusion;
    // Without any-hit shaders a non-opaque candidate is simply accepted, as an
    // opaque one is: opacity then only matters to the CULL_*/FORCE_NON_OPAQUE flags.
    const AccelManager& accel = engine->accel();
    const bool opaqueInEffect = accel.allOpaque() || !engine->shaders().anyHitGroupHasAnyHit();
    ctx.filterFree = opaqueInEffect && !accel.anyProcedural() && !(args.rayFlags & kCandidateFlags) && !needsFirstHitStop;
    if (ctx.filterFree) ctx.embree.filter = nullptr;
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

// Filter-free path: the committed hit straight from Embree's result, with
// its HitKind and record computed once, after traversal. The facing test
// dot(objectDir, Ng) equals dot(worldDir, normalFromObject * Ng).
void commitAfterTraversal(const PipelineContext& ctx, std::uint32_t lane, float t, std::uint32_t instID,
                          std::uint32_t geomID, std::uint32_t primID, const vec3& objectNormal, float u, float v,
                          CommittedHit& out, TraceCounters& counters) {
    const InstanceFacts& facts = ctx.engine->accel().instanceFacts(instID);
    const vec3& d = ctx.rays[lane].direction;
    // dot(d, N n) = dot(N^T d, n) with N = normalFromObject (column-major mat3).
    const mat3& n = facts.normalFromObject;
    const float facing = objectNormal.x * glm::dot(n[0], d) + objectNormal.y * glm::dot(n[1], d) +
                         objectNormal.z * glm::dot(n[2], d);
    bool front = facing < 0.f;
    if (facts.frontCounterClockwise) front = !front;
    const std::uint32_t type = ctx.args.rayContribution & 0xf;
    ++counters.rays[type];
    ++counters.hits[type];
    out.hit = true;
    out.t = t;
    out.instanceIndex = instID;
    out.geometryIndex = geomID;
    out.primitiveIndex = primID;
    out.hitKind = front ? kHitKindTriangleFrontFace : kHitKindTriangleBackFace;
    out.hitGroupRecord = ctx.engine->hitGroupRecord(ctx.args, instID, geomID);
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
    if (!isPipelineContext(a->context)) return;  // non-pipeline traces see no procedural hits
    auto& ctx = *reinterpret_cast<PipelineContext*>(a->context);
    RTCRayN* rayN = rayOf(a);
    for (unsigned i = 0; i < a->N; ++i) {
        if (a->valid[i] == 0) continue;
        const std::uint32_t lane = RTCRayN_id(rayN, a->N, i);
        if (ctx.ended[lane] || ctx.error) continue;
        if (ctx.args.rayFlags & RayFlag::SkipProceduralPrimitives) continue;
        const std::uint32_t instanceIndex = a->context->instID[0];
        const AccelManager& accel = ctx.engine->accel();
        const ecs::InstanceSnapshot& inst = accel.instance(instanceIndex);
        // DXR culls a procedural primitive by opacity before its intersection shader runs.
        if (culledByOpacity(isOpaque(accel.geometryInfo(inst.mesh, a->geomID), inst, ctx.args.rayFlags),
                            ctx.args.rayFlags))
            continue;
        std::uint32_t record = 0;
        try {
            record = ctx.engine->hitGroupRecord(ctx.args, instanceIndex, a->geomID);
            if (!ctx.engine->shaders().hasIntersection(record))
                throw PipelineError("hit group " + std::to_string(record) +
                                    " has no intersection shader but is used by procedural geometry");
        } catch (...) {
            ctx.error = std::current_exception();
            continue;
        }
        const RayDesc& ray = ctx.rays[lane];
        IntersectionContext ic;
        ic.worldRayOrigin = ray.origin;
        ic.worldRayDirection = ray.direction;
        ic.rayTMin = ray.tMin;
        // Embree's tfar sits one float below TMax until the first commit (open interval).
        ic.rayTCurrent = ctx.committedAny[lane] ? RTCRayN_tfar(rayN, a->N, i) : ray.tMax;
        ic.rayFlags = ctx.args.rayFlags;
        ic.instanceIndex = instanceIndex;
        ic.instanceId = inst.instanceId;
        ic.geometryIndex = a->geomID;
        ic.primitiveIndex = a->primID;
        ic.recursionDepth = ctx.depth;
        ic.instance = &inst;

        // ReportHit(): filter the candidate like a triangle hit, then commit.
        struct ReportState {
            const Args* a;
            PipelineContext* ctx;
            RTCRayN* rayN;
            unsigned i;
            std::uint32_t lane;
            std::uint32_t instanceIndex;
            bool occlusion;
            IntersectionContext* ic;
        } state{a, &ctx, rayN, i, lane, instanceIndex, occlusion, &ic};
        ic.bind(&state, [](void* p, float t, std::uint32_t hitKind, const HitAttributes& attrs) -> bool {
            auto& s = *static_cast<ReportState*>(p);
            PipelineContext& c = *s.ctx;
            if (hitKind >= 128) {
                if (!c.error) c.error = std::make_exception_ptr(PipelineError("ReportHit: hitKind must be < 128"));
                return false;
            }
            const float tCurrent = c.committedAny[s.lane] ? RTCRayN_tfar(s.rayN, s.a->N, s.i) : c.rays[s.lane].tMax;
            if (!(t > c.rays[s.lane].tMin && t < tCurrent) || c.ended[s.lane]) return false;
            c.pendingHitKind = hitKind;
            c.pendingAttributes = attrs;
            const bool keep = filterCandidate(c, s.lane, t, s.instanceIndex, s.a->geomID, s.a->primID, vec3(0.f), vec3(0.f),
                                              0.f, 0.f);
            if (!keep) return false;
            // Commit into Embree's ray/hit so traversal shrinks the interval.
            if (s.occlusion) {
                RTCRayN_tfar(s.rayN, s.a->N, s.i) = -kInfinity;  // Embree's "occluded"
            } else {
                RTCRayN_tfar(s.rayN, s.a->N, s.i) = t;
                RTCHitN* hitN = hitOf(s.a);
                RTCHitN_geomID(hitN, s.a->N, s.i) = s.a->geomID;
                RTCHitN_primID(hitN, s.a->N, s.i) = s.a->primID;
                RTCHitN_instID(hitN, s.a->N, s.i, 0) = s.instanceIndex;
                RTCHitN_u(hitN, s.a->N, s.i) = 0.f;
                RTCHitN_v(hitN, s.a->N, s.i) = 0.f;
                RTCHitN_Ng_x(hitN, s.a->N, s.i) = 0.f;
                RTCHitN_Ng_y(hitN, s.a->N, s.i) = 0.f;
                RTCHitN_Ng_z(hitN, s.a->N, s.i) = 1.f;
            }
            s.ic->rayTCurrent = t;
            return true;
        });
        ++ctx.counters->intersectionInvocations;
        try {
            ctx.engine->shaders().intersection(record, ic, ctx.payloads[lane]);
        } catch (...) {
            if (!ctx.error) ctx.error = std::current_exception();
        }
    }
}

void finishLane(const PipelineContext& ctx, std::uint32_t lane, bool hit, float t, std::uint32_t instID,
                std::uint32_t geomID, std::uint32_t primID, CommittedHit& out, TraceCounters& counters) {
    const std::uint32_t type = ctx.args.rayContribution & 0xf;
    ++counters.rays[type];
    if (!hit) {
        ++counters.misses[type];
        out.hit = false;
        out.t = kInfinity;
        return;
    }
    ++counters.hits[type];
    out.hit = true;
    out.t = t;
    out.instanceIndex = instID;
    out.geometryIndex = geomID;
    out.primitiveIndex = primID;
    out.hitKind = ctx.committedHitKind[lane];
    out.hitGroupRecord = ctx.committedRecord[lane];
    out.attributes.values = ctx.committedAttributes[lane];
}

}  // namespace

void proceduralBoundsCallback(const RTCBoundsFunctionArguments* args) {
    storeEmbreeBounds(args->bounds_o, static_cast<const Aabb*>(args->geometryUserPtr)[args->primID]);
}

namespace {

// Watertight triangles (AccelOptions::watertight): the Woop-Benthin-Wald test
// on the object-space ray Embree hands us. Inside a pipeline trace the
// candidate goes through the same DXR filter as a native triangle; otherwise
// (filter-free fast path, plain Embree queries) the nearest hit is committed.
template <class Args>
void intersectWatertightTriangles(const Args* a, bool occlusion) {
    const auto& mesh = *static_cast<const WatertightTriangles*>(a->geometryUserPtr);
    const std::uint32_t* tri = &mesh.indices[3 * a->primID];
    const vec3& p0 = mesh.positions[tri[0]];
    const vec3& p1 = mesh.positions[tri[1]];
    const vec3& p2 = mesh.positions[tri[2]];
    RTCRayN* rayN = rayOf(a);
    const bool pipeline = isPipelineContext(a->context);
    const std::uint32_t instanceIndex = a->context->instID[0];
    for (unsigned i = 0; i < a->N; ++i) {
        if (a->valid[i] == 0) continue;
        const vec3 o(RTCRayN_org_x(rayN, a->N, i), RTCRayN_org_y(rayN, a->N, i), RTCRayN_org_z(rayN, a->N, i));
        const vec3 d(RTCRayN_dir_x(rayN, a->N, i), RTCRayN_dir_y(rayN, a->N, i), RTCRayN_dir_z(rayN, a->N, i));
        float& tfar = RTCRayN_tfar(rayN, a->N, i);
        // Embree's interval [tnear, tfar] is inclusive at tnear (pipeline traces
        // already moved it one float up, making DXR's open interval); the
        // watertight test's lower end is exclusive, so step one float down.
        const float tnearInclusive = RTCRayN_tnear(rayN, a->N, i);
        const float tnear = tnearInclusive > 0.f ? std::bit_cast<float>(std::bit_cast<std::uint32_t>(tnearInclusive) - 1u)
                                                 : -std::numeric_limits<float>::denorm_min();
        const std::optional<TriangleHit> hit = intersectTriangleWatertight(o, d, p0, p1, p2, tnear, tfar);
        if (!hit) continue;
        const vec3 ng = glm::cross(p1 - p0, p2 - p0);
        if (pipeline) {
            auto& ctx = *reinterpret_cast<PipelineContext*>(a->context);
            const std::uint32_t lane = RTCRayN_id(rayN, a->N, i);
            if (!filterCandidate(ctx, lane, hit->t, instanceIndex, a->geomID, a->primID, d, ng, hit->b1, hit->b2))
                continue;
        }
        if (occlusion) {
            tfar = -kInfinity;  // Embree's "occluded"
            continue;
        }
        tfar = hit->t;
        RTCHitN* h = hitOf(a);
        RTCHitN_u(h, a->N, i) = hit->b1;
        RTCHitN_v(h, a->N, i) = hit->b2;
        RTCHitN_Ng_x(h, a->N, i) = ng.x;
        RTCHitN_Ng_y(h, a->N, i) = ng.y;
        RTCHitN_Ng_z(h, a->N, i) = ng.z;
        RTCHitN_geomID(h, a->N, i) = a->geomID;
        RTCHitN_primID(h, a->N, i) = a->primID;
        RTCHitN_instID(h, a->N, i, 0) = instanceIndex;
    }
}

}  // namespace

void watertightIntersectCallback(const RTCIntersectFunctionNArguments* args) { intersectWatertightTriangles(args, false); }
void watertightOccludedCallback(const RTCOccludedFunctionNArguments* args) { intersectWatertightTriangles(args, true); }

void proceduralIntersectCallback(const RTCIntersectFunctionNArguments* args) { runIntersectionShader(args, false); }
void proceduralOccludedCallback(const RTCOccludedFunctionNArguments* args) { runIntersectionShader(args, true); }

TraceEngine::TraceEngine(const AccelManager& accel, const ShaderTableView& shaders, std::uint32_t rayTypeCount)
    : accel_(accel), shaders_(shaders), rayTypeCount_(rayTypeCount), hitGroupCount_(shaders.hitGroupCount()) {}

void TraceEngine::throwRecordOutOfRange(std::uint64_t record, std::uint32_t instanceIndex,
                                        std::uint32_t geometryIndex) const {
    throw PipelineError("hit group record " + std::to_string(record) + " out of range (table has " +
                        std::to_string(hitGroupCount_) + "; instance " + std::to_string(instanceIndex) +
                        ", geometry " + std::to_string(geometryIndex) + ")");
}

CommittedHit TraceEngine::trace(const TraceArgs& args, const RayDesc& ray, void* payload, std::uint32_t depth,
                                TraceCounters& counters) const {
    CommittedHit out;
    void* payloads[1] = {payload};
    // A single ray is a one-lane trace; no packet overhead for Embree.
    PipelineContext ctx;
    initContext(ctx, this, args, depth, counters, &ray, payloads, false);
    const std::uint32_t type = args.rayContribution & 0xf;
    if (!isFinite(ray.origin) || !isFinite(ray.direction) || std::isnan(ray.tMin) || std::isnan(ray.tMax) ||
        !(ray.tMin >= 0.f) || !(ray.tMax >= ray.tMin) || !accel_.tlas()) {
        // DXR: such rays are undefined; we count them as misses.
        ++counters.rays[type];
        ++counters.misses[type];
        return out;
    }
    if (ctx.occlusion) {
        RTCRay r{};
        r.org_x = ray.origin.x; r.org_y = ray.origin.y; r.org_z = ray.origin.z;
        r.dir_x = ray.direction.x; r.dir_y = ray.direction.y; r.dir_z = ray.direction.z;
        r.tnear = openIntervalStart(ray.tMin);
        r.tfar = openIntervalEnd(ray.tMax);
        r.mask = args.instanceInclusionMask & 0xff;
        r.id = 0;
        rtcOccluded1(accel_.tlas(), &ctx.embree, &r);
        if (ctx.error) std::rethrow_exception(ctx.error);
        // Occlusion gives no hit details; the committed filter state does.
        const bool hit = r.tfar < 0.f;
        finishLane(ctx, 0, hit, hit ? ray.tMin : kInfinity, 0, 0, 0, out, counters);
        return out;
    }
    RTCRayHit rh{};
    rh.ray.org_x = ray.origin.x; rh.ray.org_y = ray.origin.y; rh.ray.org_z = ray.origin.z;
    rh.ray.dir_x = ray.direction.x; rh.ray.dir_y = ray.direction.y; rh.ray.dir_z = ray.direction.z;
    rh.ray.tnear = openIntervalStart(ray.tMin);
    rh.ray.tfar = openIntervalEnd(ray.tMax);
    rh.ray.mask = args.instanceInclusionMask & 0xff;
    rh.ray.id = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(accel_.tlas(), &ctx.embree, &rh);
    if (ctx.error) std::rethrow_exception(ctx.error);
    if (ctx.filterFree && rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
        commitAfterTraversal(ctx, 0, rh.ray.tfar, rh.hit.instID[0], rh.hit.geomID, rh.hit.primID,
                             vec3(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z), rh.hit.u, rh.hit.v, out, counters);
        return out;
    }
    finishLane(ctx, 0, rh.hit.geomID != RTC_INVALID_GEOMETRY_ID, rh.ray.tfar, rh.hit.instID[0], rh.hit.geomID,
               rh.hit.primID, out, counters);
    return out;
}

void TraceEngine::trace8(const TraceArgs& args, const RayDesc* rays, void* const* payloads, const bool* active,
                         std::uint32_t depth, CommittedHit* out, TraceCounters& counters) const {
    PipelineContext ctx;
    initContext(ctx, this, args, depth, counters, rays, payloads, true);
    alignas(32) int valid[kMaxLanes];
    alignas(32) RTCRayHit8 rh{};
    bool any = false;
    for (int i = 0; i < kMaxLanes; ++i) {
        const RayDesc& r = rays[i];
        const bool ok = active[i] && isFinite(r.origin) && isFinite(r.direction) && r.tMin >= 0.f && r.tMax >= r.tMin;
        valid[i] = ok ? -1 : 0;
        any = any || ok;
        rh.ray.org_x[i] = r.origin.x; rh.ray.org_y[i] = r.origin.y; rh.ray.org_z[i] = r.origin.z;
        rh.ray.dir_x[i] = r.direction.x; rh.ray.dir_y[i] = r.direction.y; rh.ray.dir_z[i] = r.direction.z;
        rh.ray.tnear[i] = ok ? openIntervalStart(r.tMin) : 0.f;
        rh.ray.tfar[i] = ok ? openIntervalEnd(r.tMax) : 0.f;
        rh.ray.mask[i] = args.instanceInclusionMask & 0xff;
        rh.ray.id[i] = static_cast<unsigned>(i);
        rh.ray.flags[i] = 0;
        rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
    }
    // Step: early-out on an empty mask.
    if (any && accel_.tlas()) {
        ++counters.packetsTraced;
        if (ctx.occlusion) {
            alignas(32) RTCRay8 r{};
            std::memcpy(&r, &rh.ray, sizeof r);
            rtcOccluded8(valid, accel_.tlas(), &ctx.embree, &r);
            if (ctx.error) std::rethrow_exception(ctx.error);
            for (int i = 0; i < kMaxLanes; ++i)
                if (active[i]) finishLane(ctx, i, valid[i] && r.tfar[i] < 0.f, rays[i].tMin, 0, 0, 0, out[i], counters);
            return;
        }
        rtcIntersect8(valid, accel_.tlas(), &ctx.embree, &rh);
        if (ctx.error) std::rethrow_exception(ctx.error);
        if (ctx.filterFree) {
            for (int i = 0; i < kMaxLanes; ++i) {
                if (!active[i]) continue;
                if (valid[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID)
                    commitAfterTraversal(ctx, i, rh.ray.tfar[i], rh.hit.instID[0][i], rh.hit.geomID[i],
                                         rh.hit.primID[i], vec3(rh.hit.Ng_x[i], rh.hit.Ng_y[i], rh.hit.Ng_z[i]),
                                         rh.hit.u[i], rh.hit.v[i], out[i], counters);
                else
                    finishLane(ctx, i, false, 0.f, 0, 0, 0, out[i], counters);
            }
            return;
        }
    }
    for (int i = 0; i < kMaxLanes; ++i)
        if (active[i])
            finishLane(ctx, i, valid[i] && rh.hit.geomID[i] != RTC_INVALID_GEOMETRY_ID, rh.ray.tfar[i], rh.hit.instID[0][i],
                       rh.hit.geomID[i], rh.hit.primID[i], out[i], counters);
}

}  // namespace rtlab::tracer
