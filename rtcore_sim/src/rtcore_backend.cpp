#include <rtlab/rtcore_sim/rtcore_backend.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace rtlab::rtcore_sim {
namespace {

constexpr std::size_t kMaxMismatchExamples = 8;

// The model's programmable side for one trace call: every candidate goes to
// the tracer's CandidateFilter (culling, opacity, any-hit, intersection
// shaders, ReportHit, end of search), with the model's ray index mapped to
// the pipeline's lane.
class FilterSide final : public ProgrammableSide {
public:
    FilterSide(tracer::CandidateFilter& filter, const std::vector<std::uint32_t>& laneOf)
        : filter_(filter), laneOf_(laneOf) {}

    CandidateVerdict triangle(std::uint32_t rayIndex, const TriangleCandidate& c) override {
        const std::uint32_t lane = laneOf_[rayIndex];
        const std::uint64_t anyHitsBefore = filter_.counters().anyHitInvocations;
        CandidateVerdict v;
        v.commit = filter_.triangle(lane, c.t, c.instance, c.geometry, c.primitive, c.objectDirection,
                                    c.objectGeometricNormal, c.u, c.v);
        v.shaderRan = filter_.counters().anyHitInvocations != anyHitsBefore;
        // A shader error ends every ray: the batch is abandoned after traversal.
        v.endSearch = filter_.ended(lane) || filter_.failed();
        return v;
    }

    ProceduralVerdict procedural(std::uint32_t rayIndex, const ProceduralCandidate& c) override {
        const std::uint32_t lane = laneOf_[rayIndex];
        // ReportHit may commit several times, each closer than the last; the
        // model takes the final (closest) one. The filter checks the interval
        // (TMin < t < RayTCurrent), so the verdict can be trusted.
        struct Reports {
            float current;
            bool committed = false;
        } reports{c.tClosest};
        tracer::CandidateFilter::ProceduralHooks hooks;
        hooks.state = &reports;
        hooks.currentT = [](void* s) { return static_cast<Reports*>(s)->current; };
        hooks.commit = [](void* s, float t) {
            auto& r = *static_cast<Reports*>(s);
            r.current = t;
            r.committed = true;
        };
        ProceduralVerdict v;
        v.shaderRan = filter_.procedural(lane, c.instance, c.geometry, c.primitive, hooks);
        v.commit = reports.committed;
        v.t = reports.current;
        v.endSearch = filter_.ended(lane) || filter_.failed();
        return v;
    }

private:
    tracer::CandidateFilter& filter_;
    const std::vector<std::uint32_t>& laneOf_;
};

// The thread inside a trace call, to refuse TraceRay from an any-hit or
// intersection shader (DXR forbids it; here it would deadlock).
thread_local const RtCoreBackend* tTracing = nullptr;

}  // namespace

static double relativeDifference(float a, float b) {
    const double scale = std::max(std::abs(double(a)), std::abs(double(b)));
    return scale > 0.0 ? std::abs(double(a) - double(b)) / scale : 0.0;
}

bool sameHit(const tracer::CommittedHit& a, const tracer::CommittedHit& b, bool hitOnly, double relativeTolerance) {
    if (a.hit != b.hit) return false;
    if (!a.hit || hitOnly) return true;
    if (a.instanceIndex != b.instanceIndex || a.geometryIndex != b.geometryIndex ||
        a.primitiveIndex != b.primitiveIndex || a.hitKind != b.hitKind || a.hitGroupRecord != b.hitGroupRecord)
        return false;
    return relativeDifference(a.t, b.t) <= relativeTolerance;
}

static bool bitIdenticalHit(const tracer::CommittedHit& a, const tracer::CommittedHit& b) {
    if (!sameHit(a, b, false, 0.0)) return false;
    if (!a.hit) return true;
    return std::memcmp(&a.t, &b.t, sizeof(float)) == 0 &&
           std::memcmp(a.attributes.values.data(), b.attributes.values.data(), sizeof(float) * 8) == 0;
}

RtCoreBackend::RtCoreBackend(const RtCoreConfig& config) : config_(config), model_(config.bvh) {
    config_.validate("rtcore configuration");
    core_ = std::make_unique<RtCore>(config_, model_);
}

RtCoreBackend::~RtCoreBackend() = default;

ModelUpdateStats RtCoreBackend::update(const ecs::SceneSnapshot& scene) {
    const std::lock_guard lock(mutex_);
    return model_.update(scene);
}

void RtCoreBackend::beginFrame() {
    const std::lock_guard lock(mutex_);
    core_->resetStats();
    primary_.clear();
    verifyStats_ = VerifyStats{};
    traceCalls_ = 0;
    invalidRays_ = 0;
}

nlohmann::json RtCoreBackend::statsJson() const {
    nlohmann::json j = core_->statsJson();
    j["backend"] = {{"traceCalls", traceCalls_}, {"invalidRaysCountedAsMisses", invalidRays_}};
    return j;
}

void RtCoreBackend::trace(const tracer::TraceEngine& engine, const tracer::TraceArgs& args, const tracer::RayDesc* rays,
                          void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
                          tracer::CommittedHit* out, tracer::TraceCounters& counters) {
    if (tTracing == this)
        throw tracer::PipelineError("TraceRay called from an any-hit or intersection shader (not allowed by DXR)");
    const std::lock_guard lock(mutex_);
    tTracing = this;
    struct Leave {
        ~Leave() { tTracing = nullptr; }
    } leave;
    ++traceCalls_;

    // Step: the rays the model sees (valid, active lanes), in lane order.
    simRays_.clear();
    laneOf_.clear();
    const std::uint8_t mask = static_cast<std::uint8_t>(args.instanceInclusionMask & 0xff);
    for (std::uint32_t lane = 0; lane < count; ++lane) {
        if (!active[lane]) continue;
        const tracer::RayDesc& r = rays[lane];
        if (!tracer::isValidRay(r)) {
            ++invalidRays_;
            continue;
        }
        SimRay s;
        s.ray.origin = r.origin;
        s.ray.tMin = r.tMin;
        s.ray.direction = r.direction;
        s.ray.tMax = r.tMax;
        s.ray.mask = mask;
        s.rayType = args.rayContribution & 0xf;
        s.skipTriangles = (args.rayFlags & tracer::RayFlag::SkipTriangles) != 0;
        s.skipProcedural = (args.rayFlags & tracer::RayFlag::SkipProceduralPrimitives) != 0;
        simRays_.push_back(s);
        laneOf_.push_back(lane);
    }

    // Step: simulate the batch; candidates go through the shared DXR filter.
    lanes_.assign(count, tracer::LaneCommitState{});
    tracer::CandidateFilter filter(engine, args, depth, counters, rays, payloads, lanes_.data());
    results_.resize(simRays_.size());
    FilterSide side(filter, laneOf_);
    core_->run(simRays_, side, results_);
    filter.rethrowIfFailed();

    // Step: committed hits (HitKind, record and attributes come from the filter).
    // Lanes in order: traced ones (laneOf_ is increasing) from the model, the
    // rest (invalid rays) as misses.
    std::size_t next = 0;
    for (std::uint32_t lane = 0; lane < count; ++lane) {
        if (!active[lane]) continue;
        if (next < laneOf_.size() && laneOf_[next] == lane) {
            const ModelHit& h = results_[next++].hit;
            filter.finish(lane, h.hit, h.t, h.instanceIndex, h.geometryIndex, h.primitiveIndex, out[lane]);
        } else {
            filter.finish(lane, false, 0.f, 0, 0, 0, out[lane]);
        }
    }

    // Step: per-ray records of primary rays (depth 1, ray type 0), in submission (lane) order.
    if (recordPrimary_ && depth == 1 && (args.rayContribution & 0xf) == 0) {
        std::size_t i = 0;
        for (std::uint32_t lane = 0; lane < count; ++lane) {
            if (!active[lane]) continue;
            PrimaryRayRecord rec;
            if (i < laneOf_.size() && laneOf_[i] == lane) {
                rec.cycles = results_[i].cycles;
                rec.slotCycles = results_[i].slotCycles;
                rec.nodeVisits = results_[i].work.nodeVisits;
                ++i;
            }
            primary_.push_back(rec);
        }
    }

    if (verify_) verifyBatch(engine, args, rays, payloads, active, count, depth, out);
}

void RtCoreBackend::verifyBatch(const tracer::TraceEngine& engine, const tracer::TraceArgs& args,
                                const tracer::RayDesc* rays, void* const* payloads, const bool* active,
                                std::size_t count, std::uint32_t depth, const tracer::CommittedHit* out) {
    // Embree's counters are kept apart: the frame's statistics are the model's.
    tracer::TraceCounters scratch;
    const bool hitOnly = (args.rayFlags & tracer::RayFlag::AcceptFirstHitAndEndSearch) != 0;
    for (std::uint32_t lane = 0; lane < count; ++lane) {
        if (!active[lane]) continue;
        const tracer::CommittedHit embree = engine.trace(args, rays[lane], payloads[lane], depth, scratch);
        ++verifyStats_.rays;
        if (hitOnly) ++verifyStats_.anyHitOnlyRays;
        const tracer::CommittedHit& model = out[lane];
        if (!sameHit(model, embree, hitOnly)) {
            ++verifyStats_.mismatches;
            if (verifyStats_.examples.size() < kMaxMismatchExamples)
                verifyStats_.examples.push_back(
                    HitMismatch{args.rayContribution & 0xf, depth, rays[lane], model, embree});
        } else if (!hitOnly) {
            if (!bitIdenticalHit(model, embree)) ++verifyStats_.notBitIdentical;
            if (model.hit)
                verifyStats_.maxRelativeTDifference =
                    std::max(verifyStats_.maxRelativeTDifference, relativeDifference(model.t, embree.t));
        }
    }
}

}  // namespace rtlab::rtcore_sim
