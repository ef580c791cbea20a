#pragma once
// A brute-force traversal back end for tests: every ray is tested against
// every triangle and procedural box of every instance (instance mask
// applied), in instance / geometry / primitive order, with the same
// double-precision watertight triangle test as the Embree back end and the
// shared CandidateFilter for the DXR rules. No acceleration structure, so a
// conformance test that passes here and on Embree checks the rules, not
// Embree. Selected for the conformance suite by the environment variable
// RTLAB_CONFORMANCE_BACKEND=reference (see tests/CMakeLists.txt).
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/tracer/candidate_filter.hpp>
#include <rtlab/tracer/instance_transform.hpp>
#include <rtlab/tracer/watertight_triangle.hpp>

#ifdef RTLAB_CONFORMANCE_WITH_RTCORE
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#endif

#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>

namespace rtlab::tracer::testing {

class ReferenceBackend final : public TraversalBackend {
public:
    explicit ReferenceBackend(const ecs::SceneSnapshot& scene) : scene_(scene) {}
    std::string_view name() const override { return "reference"; }
    bool orderDependent() const override { return false; }

    void trace(const TraceEngine& engine, const TraceArgs& args, const RayDesc* rays, void* const* payloads,
               const bool* active, std::size_t count, std::uint32_t depth, CommittedHit* out,
               TraceCounters& counters) override {
        std::vector<LaneCommitState> lanes(count);
        CandidateFilter filter(engine, args, depth, counters, rays, payloads, lanes.data());
        for (std::uint32_t lane = 0; lane < count; ++lane) {
            if (!active[lane]) continue;
            const RayDesc& ray = rays[lane];
            Closest best;
            best.t = ray.tMax;
            if (isValidRay(ray)) traceOne(engine, args, filter, lane, ray, best);
            filter.finish(lane, best.hit, best.t, best.instance, best.geometry, best.primitive, out[lane]);
        }
        filter.rethrowIfFailed();
    }

private:
    struct Closest {
        bool hit = false;
        float t = kInfinity;
        std::uint32_t instance = 0, geometry = 0, primitive = 0;
    };

    void traceOne(const TraceEngine& engine, const TraceArgs& args, CandidateFilter& filter, std::uint32_t lane,
                  const RayDesc& ray, Closest& best) const {
        const AccelManager& accel = engine.accel();
        for (std::uint32_t i = 0; i < accel.instanceCount(); ++i) {
            const ecs::InstanceSnapshot& inst = accel.instance(i);
            if (((args.instanceInclusionMask & inst.mask) & 0xff) == 0) continue;
            // Object-space ray: the direction is not normalised, so t is shared.
            const ObjectSpaceRay objectRay =
                toObjectSpace(objectFromWorldOf(inst.worldFromObject), ray.origin, ray.direction);
            const vec3 o = objectRay.origin, d = objectRay.direction;
            const ecs::MeshAsset& mesh = (*scene_.meshes)[inst.mesh];
            for (std::uint32_t g = 0; g < mesh.geometries.size(); ++g) {
                const ecs::Geometry& geo = mesh.geometries[g];
                if (geo.procedural()) {
                    for (std::uint32_t p = 0; p < geo.proceduralBoxes.size(); ++p) {
                        if (filter.ended(lane) || filter.failed()) return;
                        if (!hitsBox(geo.proceduralBoxes[p], o, d, ray.tMin, best.t)) continue;
                        struct State {
                            Closest* best;
                            std::uint32_t i, g, p;
                        } state{&best, i, g, p};
                        CandidateFilter::ProceduralHooks hooks;
                        hooks.state = &state;
                        hooks.currentT = [](void* s) { return static_cast<State*>(s)->best->t; };
                        hooks.commit = [](void* s, float t) {
                            auto& st = *static_cast<State*>(s);
                            *st.best = Closest{true, t, st.i, st.g, st.p};
                        };
                        filter.procedural(lane, i, g, p, hooks);
                    }
                    continue;
                }
                for (std::uint32_t p = 0; p < geo.triangleCount(); ++p) {
                    if (filter.ended(lane) || filter.failed()) return;
                    const vec3& p0 = geo.positions[geo.indices[3 * p]];
                    const vec3& p1 = geo.positions[geo.indices[3 * p + 1]];
                    const vec3& p2 = geo.positions[geo.indices[3 * p + 2]];
                    const auto hit = intersectTriangleWatertight(o, d, p0, p1, p2, ray.tMin, best.t);
                    if (!hit) continue;
                    if (filter.triangle(lane, hit->t, i, g, p, d, glm::cross(p1 - p0, p2 - p0), hit->b1, hit->b2))
                        best = Closest{true, hit->t, i, g, p};
                }
            }
        }
    }

    static bool hitsBox(const Aabb& box, const vec3& o, const vec3& d, float tMin, float tMax) {
        float t0 = tMin, t1 = tMax;
        for (int a = 0; a < 3; ++a) {
            const float inv = 1.f / d[a];
            float tn = (box.lo[a] - o[a]) * inv, tf = (box.hi[a] - o[a]) * inv;
            if (tn > tf) std::swap(tn, tf);
            if (std::isnan(tn) || std::isnan(tf)) continue;  // origin on a slab plane with d = 0
            t0 = std::max(t0, tn);
            t1 = std::min(t1, tf * 1.0000004f);
        }
        return t0 <= t1;
    }

    const ecs::SceneSnapshot& scene_;
};

// The back end the conformance suite runs on: nullptr (Embree) unless the
// environment asks for the reference back end.
inline std::unique_ptr<TraversalBackend> makeConformanceBackend(const ecs::SceneSnapshot& scene) {
    const char* name = std::getenv("RTLAB_CONFORMANCE_BACKEND");
    if (name && std::string(name) == "reference") return std::make_unique<ReferenceBackend>(scene);
#ifdef RTLAB_CONFORMANCE_WITH_RTCORE
    if (name && std::string(name) == "rtcore") {
        auto backend = std::make_unique<rtcore_sim::RtCoreBackend>(rtcore_sim::RtCoreConfig{});
        backend->update(scene);
        return backend;
    }
#endif
    if (name && *name) throw std::invalid_argument(std::string("RTLAB_CONFORMANCE_BACKEND: unknown back end ") + name);
    return nullptr;
}

}  // namespace rtlab::tracer::testing
