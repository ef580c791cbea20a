#include <rtlab/tracer/candidate_filter.hpp>

#include <string>

namespace rtlab::tracer {

bool isOpaque(const GeometryInfo& geometry, const ecs::InstanceSnapshot& instance, std::uint32_t rayFlags) {
    bool opaque = geometry.opaque;
    if (instance.flags & InstanceFlag::ForceOpaque) opaque = true;
    if (instance.flags & InstanceFlag::ForceNonOpaque) opaque = false;
    if (rayFlags & RayFlag::ForceOpaque) opaque = true;
    if (rayFlags & RayFlag::ForceNonOpaque) opaque = false;
    return opaque;
}

bool culledByOpacity(bool opaque, std::uint32_t rayFlags) {
    return opaque ? (rayFlags & RayFlag::CullOpaque) != 0 : (rayFlags & RayFlag::CullNonOpaque) != 0;
}

bool CandidateFilter::triangle(std::uint32_t lane, float t, std::uint32_t instance, std::uint32_t geometry,
                               std::uint32_t primitive, const vec3& objectDirection, const vec3& objectGeometricNormal,
                               float u, float v) {
    if (lanes_[lane].ended || error_) return false;
    const std::uint32_t flags = args_.rayFlags;
    // Step: triangles — skipping and face culling.
    if (flags & RayFlag::SkipTriangles) return false;
    const ecs::InstanceSnapshot& inst = engine_->accel().instance(instance);
    // DXR: front face = clockwise seen from the ray origin in a left-handed
    // frame, i.e. dot(direction, (v1-v0)x(v2-v0)) < 0 numerically.
    bool front = glm::dot(objectDirection, objectGeometricNormal) < 0.f;
    if (inst.flags & InstanceFlag::TriangleFrontCounterClockwise) front = !front;
    if (!(inst.flags & InstanceFlag::TriangleCullDisable)) {
        if ((flags & RayFlag::CullBackFacingTriangles) && !front) return false;
        if ((flags & RayFlag::CullFrontFacingTriangles) && front) return false;
    }
    HitAttributes attributes;
    attributes.values[0] = u;
    attributes.values[1] = v;
    return decide(lane, t, instance, geometry, primitive, front ? kHitKindTriangleFrontFace : kHitKindTriangleBackFace,
                  attributes);
}

bool CandidateFilter::decide(std::uint32_t lane, float t, std::uint32_t instance, std::uint32_t geometry,
                             std::uint32_t primitive, std::uint32_t hitKind, const HitAttributes& attributes) {
    const RayDesc& ray = rays_[lane];
    // Step: the ray is the open interval (TMin, TMax).
    if (!(t > ray.tMin && t < ray.tMax)) return false;
    const AccelManager& accel = engine_->accel();
    const ecs::InstanceSnapshot& inst = accel.instance(instance);
    const GeometryInfo& geo = accel.geometryInfo(inst.mesh, geometry);
    const std::uint32_t flags = args_.rayFlags;

    // Step: opacity — geometry flag, then instance overrides, then ray overrides.
    const bool opaque = isOpaque(geo, inst, flags);
    if (culledByOpacity(opaque, flags)) return false;

    std::uint32_t record = 0;
    try {
        record = engine_->hitGroupRecord(args_, instance, geometry);
    } catch (...) {
        error_ = std::current_exception();
        return false;
    }

    // Step: any-hit for non-opaque candidates.
    bool endSearch = (flags & RayFlag::AcceptFirstHitAndEndSearch) != 0;
    const ShaderTableView& shaders = engine_->shaders();
    if (!opaque && shaders.hasAnyHit(record)) {
        ++counters_->anyHitInvocations;
        // Any-hit sees the candidate as closest-hit would see a committed hit.
        CommittedHit candidate;
        candidate.t = t;
        candidate.instanceIndex = instance;
        candidate.geometryIndex = geometry;
        candidate.primitiveIndex = primitive;
        candidate.hitKind = hitKind;
        const HitContext hc = engine_->hitContext(args_, ray, candidate, depth_);
        AnyHitResult result = AnyHitResult::Ignore;
        try {
            result = shaders.anyHit(record, hc, payloads_[lane], attributes);
        } catch (...) {
            error_ = std::current_exception();
            return false;
        }
        if (result == AnyHitResult::Ignore) return false;
        if (result == AnyHitResult::AcceptAndEndSearch) endSearch = true;
    }

    // Step: commit.
    LaneCommitState& state = lanes_[lane];
    state.attributes = attributes.values;
    state.hitKind = hitKind;
    state.record = record;
    state.committedAny = true;
    if (endSearch) state.ended = true;
    return true;
}

bool CandidateFilter::procedural(std::uint32_t lane, std::uint32_t instance, std::uint32_t geometry,
                                 std::uint32_t primitive, const ProceduralHooks& hooks) {
    if (lanes_[lane].ended || error_) return false;
    if (args_.rayFlags & RayFlag::SkipProceduralPrimitives) return false;
    const AccelManager& accel = engine_->accel();
    const ecs::InstanceSnapshot& inst = accel.instance(instance);
    // DXR culls a procedural primitive by opacity before its intersection shader runs.
    if (culledByOpacity(isOpaque(accel.geometryInfo(inst.mesh, geometry), inst, args_.rayFlags), args_.rayFlags))
        return false;
    std::uint32_t record = 0;
    try {
        record = engine_->hitGroupRecord(args_, instance, geometry);
        if (!engine_->shaders().hasIntersection(record))
            throw PipelineError("hit group " + std::to_string(record) +
                                " has no intersection shader but is used by procedural geometry");
    } catch (...) {
        error_ = std::current_exception();
        return false;
    }
    const RayDesc& ray = rays_[lane];
    IntersectionContext ic;
    ic.worldRayOrigin = ray.origin;
    ic.worldRayDirection = ray.direction;
    ic.rayTMin = ray.tMin;
    ic.rayTCurrent = hooks.currentT(hooks.state);
    ic.rayFlags = args_.rayFlags;
    ic.instanceIndex = instance;
    ic.instanceId = inst.instanceId;
    ic.geometryIndex = geometry;
    ic.primitiveIndex = primitive;
    ic.recursionDepth = depth_;
    ic.instance = &inst;

    // ReportHit(): filter the candidate like a triangle hit, then commit.
    struct ReportState {
        CandidateFilter* filter;
        const ProceduralHooks* hooks;
        std::uint32_t lane, instance, geometry, primitive;
        IntersectionContext* ic;
    } state{this, &hooks, lane, instance, geometry, primitive, &ic};
    ic.bind(&state, [](void* p, float t, std::uint32_t hitKind, const HitAttributes& attributes) -> bool {
        auto& s = *static_cast<ReportState*>(p);
        CandidateFilter& f = *s.filter;
        if (hitKind >= 128) {
            if (!f.error_) f.error_ = std::make_exception_ptr(PipelineError("ReportHit: hitKind must be < 128"));
            return false;
        }
        if (f.lanes_[s.lane].ended || f.error_) return false;
        if (!(t > f.rays_[s.lane].tMin && t < s.hooks->currentT(s.hooks->state))) return false;
        if (!f.decide(s.lane, t, s.instance, s.geometry, s.primitive, hitKind, attributes)) return false;
        s.hooks->commit(s.hooks->state, t);
        s.ic->rayTCurrent = t;
        return true;
    });
    ++counters_->intersectionInvocations;
    try {
        engine_->shaders().intersection(record, ic, payloads_[lane]);
    } catch (...) {
        if (!error_) error_ = std::current_exception();
    }
    return true;
}

void CandidateFilter::finish(std::uint32_t lane, bool hit, float t, std::uint32_t instance, std::uint32_t geometry,
                             std::uint32_t primitive, CommittedHit& out) const {
    const std::uint32_t type = args_.rayContribution & 0xf;
    ++counters_->rays[type];
    if (!hit) {
        ++counters_->misses[type];
        out.hit = false;
        out.t = kInfinity;
        return;
    }
    ++counters_->hits[type];
    const LaneCommitState& state = lanes_[lane];
    out.hit = true;
    out.t = t;
    out.instanceIndex = instance;
    out.geometryIndex = geometry;
    out.primitiveIndex = primitive;
    out.hitKind = state.hitKind;
    out.hitGroupRecord = state.record;
    out.attributes.values = state.attributes;
}

}  // namespace rtlab::tracer
