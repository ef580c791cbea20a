#pragma once
// A DXR-semantic ray-tracing pipeline over Embree.
//
// Shader stages are C++ callables. A Pipeline<Payload> owns a shader binding
// table (hit groups {closest-hit, any-hit, intersection} and miss shaders)
// and implements TraceRay with DXR meaning for every ray flag, instance flag,
// the instance mask, TMin/TMax, any-hit outcomes and recursion limits:
//
//   hit-group record = (RayContributionToHitGroupIndex & 0xf)
//                    + (MultiplierForGeometryContributionToHitGroupIndex & 0xf) * GeometryIndex
//                    + InstanceContributionToHitGroupIndex
//   miss record      = MissShaderIndex
//
// Out-of-range records, missing intersection shaders and recursion past the
// limit raise PipelineError. The traversal itself lives in a type-erased
// TraceEngine (embree_backend.hpp) or a TraversalBackend
// (traversal_backend.hpp); this header only adapts types.
#include <rtlab/core/parallel.hpp>
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/dxr.hpp>
#include <rtlab/tracer/embree_backend.hpp>
#include <rtlab/tracer/traversal_backend.hpp>

#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <type_traits>
#include <string>
#include <string_view>
#include <vector>

namespace rtlab::tracer {

// Per-thread state of the ray-tracing call stack (recursion depth and the
// counters of the tile being worked on). `thread` is the launch thread
// (pixel) whose shader is running, for back ends that time launches
// (TraversalBackend::beginLaunch): a dispatch numbers its pixels tile by
// tile (16x16 tiles in row-major order, pixels row-major inside a tile), so
// that a warp of 32 threads is two rows of a tile.
struct TraceScope {
    std::uint32_t depth = 0;
    TraceCounters* counters = nullptr;
    std::uint32_t threadBase = 0;  // the first thread of the tile being worked on
    std::uint32_t thread = 0;      // the thread of lane 0 of the next trace call
};
TraceScope& currentTraceScope();

template <class Payload>
class Pipeline final : private ShaderTableView {
public:
    using ClosestHit = std::function<void(const HitContext&, Payload&, const HitAttributes&)>;
    using AnyHit = std::function<AnyHitResult(const HitContext&, Payload&, const HitAttributes&)>;
    using Intersection = std::function<void(const IntersectionContext&, Payload&)>;
    using Miss = std::function<void(const MissContext&, Payload&)>;

    struct HitGroup {
        ClosestHit closestHit;      // optional
        AnyHit anyHit;              // optional: absent means "accept"
        Intersection intersection;  // required for procedural geometry
    };
    struct Desc {
        std::vector<HitGroup> hitGroups;  // the hit-group shader table
        std::vector<Miss> missShaders;
        std::uint32_t maxRecursionDepth = 1;  // raygen's TraceRay is depth 1
        std::uint32_t rayTypeCount = 1;       // used for automatic InstanceContributionToHitGroupIndex
    };

    // `backend` (optional, not owned) replaces Embree traversal, e.g. with the
    // RT-core model; it must outlive the pipeline.
    Pipeline(const AccelManager& accel, Desc desc, TraversalBackend* backend = nullptr)
        : desc_(std::move(desc)), backend_(backend), engine_(accel, *this, desc_.rayTypeCount) {
        if (desc_.rayTypeCount == 0 || desc_.rayTypeCount > 16) throw PipelineError("rayTypeCount must be in [1, 16]");
        if (desc_.maxRecursionDepth == 0 || desc_.maxRecursionDepth > 31)
            throw PipelineError("maxRecursionDepth must be in [1, 31] (DXR limit)");
        for (const HitGroup& g : desc_.hitGroups) anyHitShaders_ = anyHitShaders_ || static_cast<bool>(g.anyHit);
    }

    // TraceRay(): closest-hit for the committed hit (unless
    // SKIP_CLOSEST_HIT_SHADER), the miss shader otherwise.
    void traceRay(const TraceArgs& args, const RayDesc& ray, Payload& payload) const {
        TraceScope& scope = currentTraceScope();
        const std::uint32_t depth = scope.depth + 1;
        if (depth > desc_.maxRecursionDepth)
            throw PipelineError("TraceRay recursion depth " + std::to_string(depth) +
                                " exceeds the pipeline's maximum of " + std::to_string(desc_.maxRecursionDepth));
        if (args.missIndex >= desc_.missShaders.size())
            throw PipelineError("miss shader index " + std::to_string(args.missIndex) + " out of range (table has " +
                                std::to_string(desc_.missShaders.size()) + ")");
        TraceCounters local;
        TraceCounters& counters = scope.counters ? *scope.counters : local;
        CommittedHit hit;
        if (backend_) {
            void* payloadPtr = &payload;
            const bool active = true;
            backend_->trace(engine_, args, &ray, &payloadPtr, &active, 1, depth, &hit, counters);
        } else {
            hit = engine_.trace(args, ray, &payload, depth, counters);
        }
        const DepthGuard guard(scope, depth);
        finish(args, ray, hit, payload, depth, counters);
    }

    // Ray generation over a width x height grid: raygen(x, y) runs once per
    // pixel, in parallel over fixed 16x16 tiles; returns the summed counters.
    // With a back end the dispatch is a launch (TraversalBackend::beginLaunch),
    // or part of the one the caller opened.
    template <class RayGen>
    TraceCounters dispatchRays(int width, int height, RayGen&& raygen) const {
        LaunchScope launch(backend_, std::uint64_t(std::max(width, 0)) * std::uint64_t(std::max(height, 0)));
        const TraceCounters counters = forEachTile(width, height, [&](const Tile& tile) {
            TraceScope& scope = currentTraceScope();
            std::uint32_t thread = scope.threadBase;
            for (int y = tile.y0; y < tile.y1; ++y)
                for (int x = tile.x0; x < tile.x1; ++x) {
                    scope.thread = thread++;
                    raygen(x, y);
                }
        });
        launch.end();
        return counters;
    }

    // Coherent ray generation through 8-wide packets: makeRay(x, y, payload)
    // returns the ray of pixel (x, y) and initialises its payload; 8
    // horizontally adjacent pixels are traced as one packet; closest-hit/miss
    // then run per lane; done(x, y, payload) receives the result. With a
    // back end, each 16x16 tile's rays are traced as one batch. makeRay may
    // return std::optional<RayDesc>: a pixel without a ray (nullopt) is not
    // traced, not counted, and done is not called for it. `coherence` tells
    // Embree whether neighbouring pixels' rays travel together (camera rays)
    // or scatter (bounces, AO): a speed hint, the hits are the same.
    template <class MakeRay, class Done>
    TraceCounters dispatchCoherent(int width, int height, const TraceArgs& args, MakeRay&& makeRay, Done&& done,
                                   RayCoherence coherence = RayCoherence::Coherent) const {
        if (args.missIndex >= desc_.missShaders.size())
            throw PipelineError("miss shader index " + std::to_string(args.missIndex) + " out of range");
        if (backend_) {
            LaunchScope launch(backend_, std::uint64_t(std::max(width, 0)) * std::uint64_t(std::max(height, 0)));
            const TraceCounters counters = dispatchBatches(width, height, args, makeRay, done);
            launch.end();
            return counters;
        }
        return forEachTile(width, height, [&](const Tile& tile) {
            TraceScope& scope = currentTraceScope();
            TraceCounters& counters = *scope.counters;
            // Per-tile scratch, reused by every packet of the tile: trace8
            // writes every active lane's hit, inactive lanes get an empty ray.
            std::array<Payload, 8> payloads;
            std::array<RayDesc, 8> rays;
            std::array<void*, 8> payloadPtrs;
            std::array<bool, 8> active;
            std::array<CommittedHit, 8> hits;
            for (int lane = 0; lane < 8; ++lane) payloadPtrs[lane] = &payloads[lane];
            for (int y = tile.y0; y < tile.y1; ++y)
                for (int x0 = tile.x0; x0 < tile.x1; x0 += 8) {
                    bool any = false;
                    for (int lane = 0; lane < 8; ++lane) {
                        payloads[lane] = Payload{};
                        rays[lane] = RayDesc{};
                        active[lane] =
                            x0 + lane < tile.x1 && generate(makeRay, x0 + lane, y, payloads[lane], rays[lane]);
                        any = any || active[lane];
                    }
                    if (!any) continue;
                    engine_.trace8(args, rays.data(), payloadPtrs.data(), active.data(), 1, hits.data(), counters,
                                   coherence);
                    const DepthGuard guard(scope, 1);
                    for (int lane = 0; lane < 8; ++lane) {
                        if (!active[lane]) continue;
                        finish(args, rays[lane], hits[lane], payloads[lane], 1, counters);
                        done(x0 + lane, y, payloads[lane]);
                    }
                }
        });
    }

    const Desc& desc() const { return desc_; }
    const TraceEngine& engine() const { return engine_; }
    TraversalBackend* backend() const { return backend_; }

private:
    // Calls makeRay; false when it returned an empty std::optional (no ray).
    template <class MakeRay>
    static bool generate(MakeRay& makeRay, int x, int y, Payload& payload, RayDesc& ray) {
        using Result = std::decay_t<decltype(makeRay(x, y, payload))>;
        if constexpr (std::is_same_v<Result, RayDesc>) {
            ray = makeRay(x, y, payload);
            return true;
        } else {
            const std::optional<RayDesc> r = makeRay(x, y, payload);
            if (!r) return false;
            ray = *r;
            return true;
        }
    }

    // dispatchCoherent on a back end: one batch per tile.
    template <class MakeRay, class Done>
    TraceCounters dispatchBatches(int width, int height, const TraceArgs& args, MakeRay& makeRay, Done& done) const {
        return forEachTile(width, height, [&](const Tile& tile) {
            TraceScope& scope = currentTraceScope();
            TraceCounters& counters = *scope.counters;
            const std::size_t n = std::size_t(tile.x1 - tile.x0) * std::size_t(tile.y1 - tile.y0);
            std::vector<Payload> payloads(n);
            std::vector<RayDesc> rays(n);
            std::vector<void*> payloadPtrs(n);
            const std::unique_ptr<bool[]> active(new bool[n]);
            std::vector<CommittedHit> hits(n);
            std::size_t i = 0, traced = 0;
            for (int y = tile.y0; y < tile.y1; ++y)
                for (int x = tile.x0; x < tile.x1; ++x, ++i) {
                    payloadPtrs[i] = &payloads[i];
                    active[i] = generate(makeRay, x, y, payloads[i], rays[i]);
                    traced += active[i];
                }
            if (traced == 0) return;
            scope.thread = scope.threadBase;
            backend_->trace(engine_, args, rays.data(), payloadPtrs.data(), active.get(), n, 1, hits.data(), counters);
            const DepthGuard guard(scope, 1);
            i = 0;
            for (int y = tile.y0; y < tile.y1; ++y)
                for (int x = tile.x0; x < tile.x1; ++x, ++i) {
                    if (!active[i]) continue;
                    scope.thread = scope.threadBase + static_cast<std::uint32_t>(i);
                    finish(args, rays[i], hits[i], payloads[i], 1, counters);
                    done(x, y, payloads[i]);
                }
        });
    }

    // Restores the depth on scope exit (closest-hit/miss may recurse).
    struct DepthGuard {
        DepthGuard(TraceScope& s, std::uint32_t depth) : scope(s), saved(s.depth) { s.depth = depth; }
        ~DepthGuard() { scope.depth = saved; }
        TraceScope& scope;
        std::uint32_t saved;
    };

    void finish(const TraceArgs& args, const RayDesc& ray, const CommittedHit& hit, Payload& payload,
                std::uint32_t depth, TraceCounters& counters) const {
        if (hit.hit) {
            if (args.rayFlags & RayFlag::SkipClosestHitShader) return;
            const ClosestHit& ch = desc_.hitGroups[hit.hitGroupRecord].closestHit;
            if (!ch) return;
            ++counters.closestHitInvocations;
            ch(engine_.hitContext(args, ray, hit, depth), payload, hit.attributes);
        } else {
            const Miss& miss = desc_.missShaders[args.missIndex];
            if (!miss) return;
            ++counters.missInvocations;
            miss(MissContext{ray.origin, ray.direction, ray.tMin, ray.tMax, args.rayFlags, depth}, payload);
        }
    }

    template <class TileFn>
    TraceCounters forEachTile(int width, int height, TileFn&& fn) const {
        const std::vector<Tile> tiles = makeTiles(width, height, 16);
        std::vector<TraceCounters> perTile(tiles.size());
        std::vector<std::uint32_t> threadBase(tiles.size(), 0);  // tile order numbers the launch's threads
        for (std::size_t i = 1; i < tiles.size(); ++i)
            threadBase[i] = threadBase[i - 1] + static_cast<std::uint32_t>((tiles[i - 1].x1 - tiles[i - 1].x0) *
                                                                           (tiles[i - 1].y1 - tiles[i - 1].y0));
        const auto runTile = [&](std::size_t i) {
            TraceScope& scope = currentTraceScope();
            const TraceScope saved = scope;
            scope = TraceScope{0, &perTile[i], threadBase[i], threadBase[i]};
            try {
                fn(tiles[i]);
            } catch (...) {
                scope = saved;
                throw;
            }
            scope = saved;
        };
        // An order-dependent back end (a simulated clock) sees the tiles in
        // order, on this thread; so does a dispatch made inside a tile (its
        // threads are numbered from 0 again: in parallel, the same thread's
        // rays would reach a back end from several host threads at once).
        const bool insideTile = currentTraceScope().counters != nullptr;
        if (backend_ && (backend_->orderDependent() || insideTile))
            for (std::size_t i = 0; i < tiles.size(); ++i) runTile(i);
        else parallelForEach(tiles.size(), runTile);
        TraceCounters total;
        for (const TraceCounters& c : perTile) total.add(c);
        return total;
    }

    // ShaderTableView
    std::size_t hitGroupCount() const override { return desc_.hitGroups.size(); }
    bool anyHitGroupHasAnyHit() const override { return anyHitShaders_; }
    bool hasAnyHit(std::uint32_t record) const override { return static_cast<bool>(desc_.hitGroups[record].anyHit); }
    AnyHitResult anyHit(std::uint32_t record, const HitContext& ctx, void* payload,
                        const HitAttributes& attributes) const override {
        return desc_.hitGroups[record].anyHit(ctx, *static_cast<Payload*>(payload), attributes);
    }
    bool hasIntersection(std::uint32_t record) const override {
        return static_cast<bool>(desc_.hitGroups[record].intersection);
    }
    void intersection(std::uint32_t record, const IntersectionContext& ctx, void* payload) const override {
        desc_.hitGroups[record].intersection(ctx, *static_cast<Payload*>(payload));
    }

    Desc desc_;
    bool anyHitShaders_ = false;
    TraversalBackend* backend_ = nullptr;
    TraceEngine engine_;
};

// The usual shader table for a scene: one record per (geometry slot, ray
// type), record = slot * rayTypeCount + rayType, so that TraceRay with
// rayContribution = ray type and multiplier = rayTypeCount (and automatic
// instance contributions) finds it. makeHitGroup(material, geometry, rayType)
// returns the shaders of one record.
template <class Payload, class MakeHitGroup>
std::vector<typename Pipeline<Payload>::HitGroup> buildMaterialShaderTable(const AccelManager& accel,
                                                                           const ecs::SceneSnapshot& scene,
                                                                           std::uint32_t rayTypeCount,
                                                                           MakeHitGroup&& makeHitGroup) {
    std::vector<typename Pipeline<Payload>::HitGroup> table(std::size_t(accel.geometrySlotCount()) * rayTypeCount);
    static const ecs::Material kDefaultMaterial{};
    for (std::size_t mesh = 0; mesh < scene.meshes->size(); ++mesh) {
        const auto id = static_cast<ecs::MeshId>(mesh);
        for (std::uint32_t g = 0; g < accel.geometryCount(id); ++g) {
            const ecs::Geometry& geometry = (*scene.meshes)[mesh].geometries[g];
            const ecs::Material& material =
                geometry.material < scene.materials->size() ? (*scene.materials)[geometry.material] : kDefaultMaterial;
            for (std::uint32_t rayType = 0; rayType < rayTypeCount; ++rayType)
                table[std::size_t(accel.geometrySlotBase(id) + g) * rayTypeCount + rayType] =
                    makeHitGroup(material, geometry, rayType);
        }
    }
    return table;
}

}  // namespace rtlab::tracer
