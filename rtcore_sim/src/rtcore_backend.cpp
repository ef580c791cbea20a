#include <rtlab/rtcore_sim/rtcore_backend.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/parallel.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>

namespace rtlab::rtcore_sim {

SimRay simRayOf(const tracer::RayDesc& r, const tracer::TraceArgs& args) {
    SimRay s;
    s.ray.origin = r.origin;
    s.ray.tMin = r.tMin;
    s.ray.direction = r.direction;
    s.ray.tMax = r.tMax;
    s.ray.mask = static_cast<std::uint8_t>(args.instanceInclusionMask & 0xff);
    s.rayType = args.rayContribution & 0xf;
    s.skipTriangles = (args.rayFlags & tracer::RayFlag::SkipTriangles) != 0;
    s.skipProcedural = (args.rayFlags & tracer::RayFlag::SkipProceduralPrimitives) != 0;
    return s;
}
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

// Words of a verdict (LaunchLog).
void appendTriangleVerdict(std::vector<std::uint32_t>& words, const CandidateVerdict& v) {
    words.push_back((v.commit ? LaunchLog::kCommit : 0u) | (v.endSearch ? LaunchLog::kEndSearch : 0u) |
                    (v.shaderRan ? LaunchLog::kShaderRan : 0u));
}
void appendProceduralVerdict(std::vector<std::uint32_t>& words, const ProceduralVerdict& v) {
    words.push_back((v.commit ? LaunchLog::kCommit : 0u) | (v.endSearch ? LaunchLog::kEndSearch : 0u) |
                    (v.shaderRan ? LaunchLog::kShaderRan : 0u) | LaunchLog::kProcedural);
    words.push_back(std::bit_cast<std::uint32_t>(v.t));
}

[[noreturn]] void verdictMismatch(std::uint32_t ray, const char* what) {
    throw InputError("recorded verdicts", "ray " + std::to_string(ray) + " " + what +
                                              " (the recording does not match this scene, configuration or bvh)");
}

// Reads verdicts from a word stream, one ray at a time.
struct VerdictReader {
    const std::uint32_t* words;
    std::uint64_t at, end;
    std::uint32_t ray;
    CandidateVerdict triangle() {
        if (at >= end || (words[at] & LaunchLog::kProcedural))
            verdictMismatch(ray, "met a triangle candidate the recording does not have");
        const std::uint32_t w = words[at++];
        return CandidateVerdict{(w & LaunchLog::kCommit) != 0, (w & LaunchLog::kEndSearch) != 0,
                                (w & LaunchLog::kShaderRan) != 0};
    }
    ProceduralVerdict procedural() {
        if (at + 1 >= end || !(words[at] & LaunchLog::kProcedural))
            verdictMismatch(ray, "met a procedural candidate the recording does not have");
        const std::uint32_t w = words[at];
        ProceduralVerdict v;
        v.commit = (w & LaunchLog::kCommit) != 0;
        v.endSearch = (w & LaunchLog::kEndSearch) != 0;
        v.shaderRan = (w & LaunchLog::kShaderRan) != 0;
        v.t = std::bit_cast<float>(words[at + 1]);
        at += 2;
        return v;
    }
};

// The functional pass of launch mode: every verdict of `inner` (the DXR
// filter, or recorded verdicts) appended to the launch's log.
class LoggingSide final : public ProgrammableSide {
public:
    LoggingSide(ProgrammableSide& inner, std::vector<std::uint32_t>& words) : inner_(inner), words_(words) {}
    CandidateVerdict triangle(std::uint32_t rayIndex, const TriangleCandidate& c) override {
        const CandidateVerdict v = inner_.triangle(rayIndex, c);
        appendTriangleVerdict(words_, v);
        return v;
    }
    ProceduralVerdict procedural(std::uint32_t rayIndex, const ProceduralCandidate& c) override {
        const ProceduralVerdict v = inner_.procedural(rayIndex, c);
        appendProceduralVerdict(words_, v);
        return v;
    }

private:
    ProgrammableSide& inner_;
    std::vector<std::uint32_t>& words_;
};

// The timing pass: each ray's verdicts, in order, from words where ray i's
// are [ends[i-1], ends[i]) (a launch's log, or one recorded tile batch). A
// ray's callbacks touch only its own cursor: concurrent.
class VerdictReplaySide final : public ProgrammableSide {
public:
    VerdictReplaySide(const std::uint32_t* words, std::span<const std::uint64_t> ends, bool recorded)
        : words_(words), ends_(ends), cursor_(ends.size()), recorded_(recorded) {
        for (std::size_t i = 1; i < cursor_.size(); ++i) cursor_[i] = ends[i - 1];
    }
    CandidateVerdict triangle(std::uint32_t i, const TriangleCandidate&) override {
        VerdictReader r = reader(i);
        const CandidateVerdict v = r.triangle();
        cursor_[i] = r.at;
        return v;
    }
    ProceduralVerdict procedural(std::uint32_t i, const ProceduralCandidate&) override {
        VerdictReader r = reader(i);
        const ProceduralVerdict v = r.procedural();
        cursor_[i] = r.at;
        return v;
    }
    bool concurrent() const override { return true; }
    // Every ray used every verdict of its own (the timing pass traversed as the functional one did).
    void checkConsumed() const {
        for (std::size_t i = 0; i < cursor_.size(); ++i)
            if (cursor_[i] != ends_[i]) {
                if (recorded_) verdictMismatch(static_cast<std::uint32_t>(i), "left recorded verdicts unused");
                throw std::logic_error("rtcore_sim: the timing pass of ray " + std::to_string(i) +
                                       " left logged verdicts unused");
            }
    }

private:
    VerdictReader reader(std::uint32_t i) const { return VerdictReader{words_, cursor_[i], ends_[i], i}; }
    const std::uint32_t* words_;
    std::span<const std::uint64_t> ends_;
    std::vector<std::uint64_t> cursor_;
    bool recorded_;
};

// Where each traced ray's recorded verdicts end (RecordedVerdicts), checked against the call.
std::vector<std::uint64_t> recordedEnds(const RecordedVerdicts& v, std::size_t rays) {
    if (v.counts.size() != rays)
        verdictMismatch(0, "batch has another number of traced rays than recorded verdict counts");
    std::vector<std::uint64_t> ends(rays);
    std::uint64_t sum = 0;
    for (std::size_t i = 0; i < rays; ++i) ends[i] = sum += v.counts[i];
    if (sum != v.words.size()) verdictMismatch(0, "batch's verdict counts do not add up");
    return ends;
}

// Tile mode, recording: each ray's verdicts logged on their own (the rays of
// a batch interleave), flattened after the batch.
class TileLoggingSide final : public ProgrammableSide {
public:
    TileLoggingSide(ProgrammableSide& inner, std::vector<std::vector<std::uint32_t>>& perRay)
        : inner_(inner), perRay_(perRay) {}
    CandidateVerdict triangle(std::uint32_t i, const TriangleCandidate& c) override {
        const CandidateVerdict v = inner_.triangle(i, c);
        appendTriangleVerdict(perRay_[i], v);
        return v;
    }
    ProceduralVerdict procedural(std::uint32_t i, const ProceduralCandidate& c) override {
        const ProceduralVerdict v = inner_.procedural(i, c);
        appendProceduralVerdict(perRay_[i], v);
        return v;
    }

private:
    ProgrammableSide& inner_;
    std::vector<std::vector<std::uint32_t>>& perRay_;
};

// The rays the model sees (valid, active lanes) and their lanes, in lane
// order; returns the invalid active lanes (misses, as on Embree).
std::uint64_t collectRays(const tracer::TraceArgs& args, const tracer::RayDesc* rays, const bool* active,
                          std::size_t count, std::vector<SimRay>& simRays, std::vector<std::uint32_t>& laneOf) {
    simRays.clear();
    laneOf.clear();
    std::uint64_t invalid = 0;
    for (std::uint32_t lane = 0; lane < count; ++lane) {
        if (!active[lane]) continue;
        if (!tracer::isValidRay(rays[lane])) {
            ++invalid;
            continue;
        }
        simRays.push_back(simRayOf(rays[lane], args));
        laneOf.push_back(lane);
    }
    return invalid;
}

// A hit found with recorded verdicts: no shader ran to say HitKind and record (0); t, ids and barycentrics.
void finishReplayed(const tracer::CandidateFilter& filter, std::uint32_t lane, const ModelHit& h,
                    tracer::CommittedHit& out) {
    filter.finish(lane, h.hit, h.t, h.instanceIndex, h.geometryIndex, h.primitiveIndex, out);
    if (!h.hit) return;
    out.hitKind = 0;
    out.hitGroupRecord = 0;
    out.attributes.values.fill(0.f);
    out.attributes.values[0] = h.b1;
    out.attributes.values[1] = h.b2;
}

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
    launches_.clear();
    verifyStats_ = VerifyStats{};
    traceCalls_ = 0;
    invalidRays_ = 0;
}

nlohmann::json RtCoreBackend::statsJson() const {
    nlohmann::json j = core_->statsJson();
    j["backend"] = {{"traceCalls", traceCalls_},
                    {"invalidRaysCountedAsMisses", invalidRays_},
                    {"launch", toString(config_.gpu.launch)}};
    nlohmann::json launches = nlohmann::json::array();
    for (const LaunchRecord& l : launches_) {
        nlohmann::json byKind = nlohmann::json::object();
        for (const auto& [kind, utilization] : l.busiestByKind) byKind[kind] = utilization;
        launches.push_back({{"rays", l.rays},
                            {"threads", l.threads},
                            {"cycles", l.cycles},
                            {"busiest", {{"resource", l.busiest}, {"utilization", l.busiestUtilization}}},
                            {"busiestByKind", std::move(byKind)}});
    }
    j["backend"]["launches"] = std::move(launches);
    return j;
}

void RtCoreBackend::trace(const tracer::TraceEngine& engine, const tracer::TraceArgs& args, const tracer::RayDesc* rays,
                          void* const* payloads, const bool* active, std::size_t count, std::uint32_t depth,
                          tracer::CommittedHit* out, tracer::TraceCounters& counters) {
    if (tTracing == this)
        throw tracer::PipelineError("TraceRay called from an any-hit or intersection shader (not allowed by DXR)");
    std::unique_lock lock(mutex_);
    struct Leave {
        const RtCoreBackend* outer = tTracing;  // another back end's call this one is nested in, if any
        ~Leave() { tTracing = outer; }
    } leave;
    tTracing = this;
    ++traceCalls_;
    // Launch mode, a call of an open launch: traced without the lock.
    if (launchMode() && launchDepth_ > 0 && !replaying_ && !keepCallVerdicts_ && !verify_) {
        lock.unlock();
        traceConcurrently(engine, args, rays, payloads, active, count, depth, out, counters);
        return;
    }

    invalidRays_ += collectRays(args, rays, active, count, simRays_, laneOf_);

    if (launchMode()) {
        traceFunctional(engine, args, rays, payloads, active, count, depth, out, counters);
        if (verify_) verifyBatch(engine, args, rays, payloads, active, count, depth, out);
        return;
    }
    const bool replaying = replaying_;
    replaying_ = false;

    // Step: simulate the batch; candidates go through the shared DXR filter
    // (or take recorded verdicts; or are logged for a recording).
    lanes_.assign(count, tracer::LaneCommitState{});
    tracer::CandidateFilter filter(engine, args, depth, counters, rays, payloads, lanes_.data());
    results_.resize(simRays_.size());
    FilterSide filterSide(filter, laneOf_);
    if (replaying) {
        const std::vector<std::uint64_t> ends = recordedEnds(replay_, simRays_.size());
        VerdictReplaySide side(replay_.words.data(), ends, true);
        core_->run(simRays_, side, results_);
        side.checkConsumed();
    } else if (keepCallVerdicts_) {
        tileVerdicts_.assign(simRays_.size(), {});
        TileLoggingSide side(filterSide, tileVerdicts_);
        core_->run(simRays_, side, results_);
        callCounts_.clear();
        callWords_.clear();
        for (const auto& v : tileVerdicts_) {
            callCounts_.push_back(static_cast<std::uint32_t>(v.size()));
            callWords_.insert(callWords_.end(), v.begin(), v.end());
        }
        callVerdicts_ = RecordedVerdicts{callCounts_, callWords_};
    } else {
        core_->run(simRays_, filterSide, results_);
    }
    filter.rethrowIfFailed();

    finishCall(filter, active, count, replaying, laneOf_, results_, out);

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

// A call's committed hits (HitKind, record and attributes come from the
// filter). Lanes in order: traced ones (laneOf is increasing) from the
// model's results, the rest (invalid rays) as misses.
void RtCoreBackend::finishCall(const tracer::CandidateFilter& filter, const bool* active, std::size_t count,
                               bool replaying, std::span<const std::uint32_t> laneOf,
                               std::span<const SimRayResult> results, tracer::CommittedHit* out) {
    std::size_t next = 0;
    for (std::uint32_t lane = 0; lane < count; ++lane) {
        if (!active[lane]) continue;
        if (next < laneOf.size() && laneOf[next] == lane) {
            const ModelHit& h = results[next++].hit;
            if (replaying) finishReplayed(filter, lane, h, out[lane]);
            else filter.finish(lane, h.hit, h.t, h.instanceIndex, h.geometryIndex, h.primitiveIndex, out[lane]);
        } else {
            filter.finish(lane, false, 0.f, 0, 0, 0, out[lane]);
        }
    }
}

// Launch mode: the call's rays answered by the functional traversal now,
// appended with their threads, parents and verdicts to the launch's log.
void RtCoreBackend::traceFunctional(const tracer::TraceEngine& engine, const tracer::TraceArgs& args,
                                    const tracer::RayDesc* rays, void* const* payloads, const bool* active,
                                    std::size_t count, std::uint32_t depth, tracer::CommittedHit* out,
                                    tracer::TraceCounters& counters) {
    // A call outside any launch is a launch of its own.
    const bool implicit = launchDepth_ == 0;
    if (implicit) beginLaunchLocked(static_cast<std::uint32_t>(count), "trace call");
    // An exception leaves a half-built log: the launch is then dropped
    // (its own, or the open one when its scope ends).
    struct Abort {
        RtCoreBackend* self;
        bool implicit;
        bool armed = true;
        ~Abort() {
            if (!armed) return;
            if (implicit) self->abortLaunchLocked();
            else self->launchFailed_ = true;
        }
    } abort{this, implicit};
    const std::uint32_t base = implicit ? 0 : tracer::currentTraceScope().thread;
    const bool replaying = replaying_;
    replaying_ = false;

    lanes_.assign(count, tracer::LaneCommitState{});
    tracer::CandidateFilter filter(engine, args, depth, counters, rays, payloads, lanes_.data());
    FilterSide filterSide(filter, laneOf_);
    // Replaying: the recorded verdicts, checked for this call's rays (a call's rays are traced one by one here).
    const std::vector<std::uint64_t> recordedEnd =
        replaying ? recordedEnds(replay_, simRays_.size()) : std::vector<std::uint64_t>{};
    VerdictReplaySide recorded(replay_.words.data(), recordedEnd, true);
    LoggingSide logging(replaying ? static_cast<ProgrammableSide&>(recorded) : filterSide, launch_.verdicts);
    lastCallFirst_ = launch_.rays.size();
    results_.resize(simRays_.size());
    growLaunchThreads(active, count, base);
    for (std::uint32_t k = 0; k < simRays_.size(); ++k) {
        // Step: the ray and its thread (its parent is its thread's previous ray in the log).
        launch_.thread.push_back(static_cast<std::uint32_t>(std::uint64_t(base) + laneOf_[k]));  // < threads
        launch_.rays.push_back(simRays_[k]);
        // Step: its hit, every verdict logged.
        TraversalCounters work;
        results_[k].hit = traceRay(model_, simRays_[k], logging, k, work);
        launch_.verdictEnd.push_back(launch_.verdicts.size());
    }
    if (replaying) recorded.checkConsumed();
    filter.rethrowIfFailed();
    if (keepCallVerdicts_) {
        callCounts_.clear();
        for (std::size_t i = lastCallFirst_; i < launch_.rays.size(); ++i)
            callCounts_.push_back(static_cast<std::uint32_t>(launch_.verdictEnd[i] - launch_.verdictBegin(i)));
        const std::uint64_t begin = launch_.verdictBegin(lastCallFirst_);
        callWords_.assign(launch_.verdicts.begin() + static_cast<std::ptrdiff_t>(begin), launch_.verdicts.end());
        callVerdicts_ = RecordedVerdicts{callCounts_, callWords_};
    }

    finishCall(filter, active, count, replaying, laneOf_, results_, out);
    recordPrimary(args, depth, active, count, laneOf_, lastCallFirst_, base);
    abort.armed = false;
    if (implicit) endLaunchLocked();
}

// A launch's cost: its cycles and the utilization of its busiest resources.
LaunchRecord RtCoreBackend::launchRecord(const LaunchLog& log, std::uint64_t cycles,
                                         const std::vector<ResourceUse>& before,
                                         const std::vector<ResourceUse>& after) const {
    LaunchRecord r{launchLabel_, log.rays.size(), log.threads, cycles, {}, "", 0.0};
    if (cycles == 0 || before.size() != after.size()) return r;
    for (std::size_t i = 0; i < after.size(); ++i) {
        const ResourceUse& u = after[i];
        const double utilization = (u.busy - before[i].busy) / (u.capacity * double(cycles));
        auto kind = std::find_if(r.busiestByKind.begin(), r.busiestByKind.end(),
                                 [&](const auto& k) { return k.first == u.kind; });
        if (kind == r.busiestByKind.end()) r.busiestByKind.emplace_back(u.kind, utilization);
        else kind->second = std::max(kind->second, utilization);
        if (utilization > r.busiestUtilization) {
            r.busiestUtilization = utilization;
            const bool shared = u.kind == "l2Bank" || u.kind == "dramChannel";
            r.busiest = u.kind + (shared ? " " : " of core ") + std::to_string(u.index);
        }
    }
    return r;
}

// Launch mode: the launch's threads grow to every active lane's (as the
// recorder counts them, invalid rays included). Under the lock.
void RtCoreBackend::growLaunchThreads(const bool* active, std::size_t count, std::uint32_t base) {
    for (std::size_t lane = count; lane-- > 0;)
        if (active[lane]) {
            const std::uint64_t last = std::uint64_t(base) + lane + 1;
            if (last > kMaxLaunchThreads) throw tracer::PipelineError("launch thread index out of range");
            launch_.threads = std::max(launch_.threads, static_cast<std::uint32_t>(last));
            return;
        }
}

// Launch mode: a call's primary rays (their threads, and their rays from
// `first` in the launch's log), recorded when their launch is simulated.
// Under the lock.
void RtCoreBackend::recordPrimary(const tracer::TraceArgs& args, std::uint32_t depth, const bool* active,
                                  std::size_t count, std::span<const std::uint32_t> laneOf, std::size_t first,
                                  std::uint32_t base) {
    if (!recordPrimary_ || depth != 1 || (args.rayContribution & 0xf) != 0) return;
    std::size_t i = 0;
    for (std::uint32_t lane = 0; lane < count; ++lane) {
        if (!active[lane]) continue;
        const bool traced = i < laneOf.size() && laneOf[i] == lane;
        launchPrimary_.push_back(LaunchPrimary{base + lane, traced ? first + i++ : kNoRay});
    }
}

// The launch's primary-ray records, in thread order (a thread's in the
// order it traced them), with the model's figures once it is simulated.
void RtCoreBackend::flushLaunchPrimary(bool simulated) {
    std::stable_sort(launchPrimary_.begin(), launchPrimary_.end(),
                     [](const LaunchPrimary& a, const LaunchPrimary& b) { return a.thread < b.thread; });
    for (const LaunchPrimary& p : launchPrimary_) {
        PrimaryRayRecord rec;
        if (simulated && p.ray != kNoRay) {
            rec.cycles = results_[p.ray].cycles;
            rec.slotCycles = results_[p.ray].slotCycles;
            rec.nodeVisits = results_[p.ray].work.nodeVisits;
        }
        primary_.push_back(rec);
    }
    launchPrimary_.clear();
}

// Launch mode, a call of an open launch (not verifying, recording or
// replaying): the functional traversal of the call's rays on this host
// thread's own buffers, without the lock, so that the calls of a launch run
// in parallel; the lock is taken only to append them to the launch's log.
// The log's order does not matter (see the header).
void RtCoreBackend::traceConcurrently(const tracer::TraceEngine& engine, const tracer::TraceArgs& args,
                                      const tracer::RayDesc* rays, void* const* payloads, const bool* active,
                                      std::size_t count, std::uint32_t depth, tracer::CommittedHit* out,
                                      tracer::TraceCounters& counters) {
    struct CallBuffers {
        std::vector<SimRay> simRays;
        std::vector<std::uint32_t> laneOf;
        std::vector<SimRayResult> results;
        std::vector<tracer::LaneCommitState> lanes;
        std::vector<std::uint32_t> verdicts;
        std::vector<std::uint64_t> verdictEnd;
    };
    // The host thread's buffers, or the call's own when they are in use
    // (a shader of this call tracing through another RtCoreBackend).
    thread_local CallBuffers threadBuffers;
    thread_local bool threadBuffersInUse = false;
    std::optional<CallBuffers> ownBuffers;
    if (threadBuffersInUse) ownBuffers.emplace();
    CallBuffers& b = ownBuffers ? *ownBuffers : threadBuffers;
    struct Release {
        bool* inUse;
        ~Release() {
            if (inUse) *inUse = false;
        }
    } release{ownBuffers ? nullptr : &threadBuffersInUse};
    if (!ownBuffers) threadBuffersInUse = true;
    // An exception drops the launch when its scope ends.
    struct Abort {
        RtCoreBackend* self;
        bool armed = true;
        ~Abort() {
            if (!armed) return;
            const std::lock_guard lock(self->mutex_);
            self->launchFailed_ = true;
        }
    } abort{this};

    const std::uint64_t invalid = collectRays(args, rays, active, count, b.simRays, b.laneOf);
    // Step: their hits, every verdict logged.
    b.lanes.assign(count, tracer::LaneCommitState{});
    tracer::CandidateFilter filter(engine, args, depth, counters, rays, payloads, b.lanes.data());
    FilterSide filterSide(filter, b.laneOf);
    b.verdicts.clear();
    b.verdictEnd.clear();
    LoggingSide logging(filterSide, b.verdicts);
    b.results.resize(b.simRays.size());
    for (std::uint32_t k = 0; k < b.simRays.size(); ++k) {
        TraversalCounters work;
        b.results[k].hit = traceRay(model_, b.simRays[k], logging, k, work);
        b.verdictEnd.push_back(b.verdicts.size());
    }
    filter.rethrowIfFailed();

    // Step: appended to the launch's log, each ray with its thread.
    const std::uint32_t base = tracer::currentTraceScope().thread;
    {
        const std::lock_guard lock(mutex_);
        if (launchDepth_ == 0) throw std::logic_error("RtCoreBackend: a launch ended while one of its calls ran");
        invalidRays_ += invalid;
        growLaunchThreads(active, count, base);
        const std::size_t first = launch_.rays.size();
        const std::uint64_t offset = launch_.verdicts.size();
        launch_.rays.insert(launch_.rays.end(), b.simRays.begin(), b.simRays.end());
        for (std::uint32_t lane : b.laneOf) launch_.thread.push_back(base + lane);  // < threads
        for (std::uint64_t end : b.verdictEnd) launch_.verdictEnd.push_back(offset + end);
        launch_.verdicts.insert(launch_.verdicts.end(), b.verdicts.begin(), b.verdicts.end());
        recordPrimary(args, depth, active, count, b.laneOf, first, base);
    }
    finishCall(filter, active, count, false, b.laneOf, b.results, out);
    abort.armed = false;
}

void LaunchLog::clear() {
    threads = 0;
    rays.clear();
    thread.clear();
    verdictEnd.clear();
    verdicts.clear();
}

void RtCoreBackend::beginLaunch(std::uint32_t threads, std::string_view label) {
    const std::lock_guard lock(mutex_);
    beginLaunchLocked(threads, label);
}
void RtCoreBackend::endLaunch() {
    const std::lock_guard lock(mutex_);
    endLaunchLocked();
}
void RtCoreBackend::abortLaunch() {
    const std::lock_guard lock(mutex_);
    abortLaunchLocked();
}

void RtCoreBackend::beginLaunchLocked(std::uint32_t threads, std::string_view label) {
    if (launchDepth_ > 0) {  // joins the open launch
        ++launchDepth_;
        return;
    }
    if (threads > kMaxLaunchThreads)
        throw tracer::PipelineError("a launch of " + std::to_string(threads) + " threads (the model takes at most " +
                                    std::to_string(kMaxLaunchThreads) + ")");
    // Room for one ray per thread (a render's launch has at least that many
    // rays), so the log does not grow by copies (capped: a sparse dispatch
    // of many threads may trace few rays). First: it may throw.
    launch_.clear();
    const std::size_t expected = std::min<std::size_t>(threads, std::size_t(1) << 23);
    reserveTouchedInParallel(launch_.rays, expected);
    reserveTouchedInParallel(launch_.thread, expected);
    reserveTouchedInParallel(launch_.verdictEnd, expected);
    launchDepth_ = 1;
    launchLabel_ = label;
    launchFailed_ = false;
    launch_.threads = threads;  // grows with the threads that trace
    launchPrimary_.clear();
}

// A scope left by an exception: the launch is dropped when its outermost scope ends.
void RtCoreBackend::abortLaunchLocked() {
    if (launchDepth_ == 0) return;
    launchFailed_ = true;
    if (--launchDepth_ > 0) return;
    launch_.clear();
    launchPrimary_.clear();
}

// The launch's timing: the whole log simulated, the verdicts replayed.
void RtCoreBackend::endLaunchLocked() {
    if (launchDepth_ == 0) throw std::logic_error("RtCoreBackend::endLaunch without beginLaunch");
    if (--launchDepth_ > 0) return;
    if (!launchMode() || launch_.rays.empty() || launchFailed_) {
        if (!launchFailed_) flushLaunchPrimary(false);  // invalid rays only
        launch_.clear();
        launchPrimary_.clear();
        launchFailed_ = false;
        return;
    }
    struct Clear {
        RtCoreBackend* self;
        ~Clear() {
            self->launch_.clear();
            self->launchPrimary_.clear();
        }
    } clear{this};
    // Per-ray results only for primary-ray records (a launch of bounces and
    // shadow rays needs none: millions of 92-byte results not written).
    const bool perRay = std::any_of(launchPrimary_.begin(), launchPrimary_.end(),
                                    [](const LaunchPrimary& p) { return p.ray != kNoRay; });
    results_.clear();  // the last launch's: not copied into new room
    if (perRay) {
        reserveTouchedInParallel(results_, launch_.rays.size());
        results_.assign(launch_.rays.size(), SimRayResult{});
    }
    VerdictReplaySide side(launch_.verdicts.data(), launch_.verdictEnd, false);
    const std::uint64_t before = core_->cycle();
    const std::vector<ResourceUse> usedBefore = core_->resourceUse();
    core_->runLaunch(launch_.rays, launch_.thread, launch_.threads, side, std::span<SimRayResult>(results_));
    side.checkConsumed();
    launches_.push_back(launchRecord(launch_, core_->cycle() - before, usedBefore, core_->resourceUse()));
    flushLaunchPrimary(true);
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
