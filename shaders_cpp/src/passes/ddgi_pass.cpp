// DDGI (Majercik et al. 2019) as the GI technique: every frame each probe of
// the volume over the scene traces raysPerProbe rays (a rotated spherical
// Fibonacci set), their hits are shaded with emission + one light (shadow
// ray) + the previous probes' irradiance (multi-bounce feedback), the
// probes blend the results with hysteresis, and every G-buffer surface
// reads its irradiance with Chebyshev visibility and trilinear weights.
#include "indirect_shading.hpp"
#include "passes.hpp"

#include <rtlab/shaders_cpp/ddgi.hpp>

#include <algorithm>

namespace rtlab::shaders::detail {
namespace {

// World bounds of each instance's geometry, in snapshot order.
std::vector<Aabb> instanceBounds(const ecs::SceneSnapshot& scene) {
    std::vector<Aabb> out;
    out.reserve(scene.instances.size());
    for (const ecs::InstanceSnapshot& inst : scene.instances) {
        Aabb bounds;
        for (const ecs::Geometry& g : (*scene.meshes)[inst.mesh].geometries) {
            for (const vec3& p : g.positions) bounds.extend(vec3(inst.worldFromObject * vec4(p, 1.f)));
            for (const Aabb& b : g.proceduralBoxes) bounds.extend(b.transformed(inst.worldFromObject));
        }
        out.push_back(bounds);
    }
    return out;
}

bool contains(const Aabb& outer, const Aabb& inner) {
    return glm::all(glm::lessThanEqual(outer.lo, inner.lo)) && glm::all(glm::greaterThanEqual(outer.hi, inner.hi));
}

bool sameBox(const Aabb& a, const Aabb& b) { return (a.empty() && b.empty()) || (a.lo == b.lo && a.hi == b.hi); }

// Probe classification follows the geometry: Idle and Inside probes trace
// nothing, so wake those around every instance that appeared, disappeared,
// moved or deformed since the previous DDGI frame (its old and new bounds).
void wakeAroundChanges(const ecs::SceneSnapshot& scene, const std::vector<Aabb>& bounds, FrameHistory& history,
                       DdgiVolume& volume) {
    std::vector<Aabb> now;
    for (std::size_t i = 0; i < scene.instances.size(); ++i) {
        const std::uint32_t e = scene.instances[i].entity.index;
        if (now.size() <= e) now.resize(e + 1);
        now[e] = bounds[i];
    }
    // Deformation (refit) or new topology: the mesh's instances, even if
    // their bounds happen to stay the same; only on a new World update.
    const bool newUpdate = !history.ddgiSeenUpdate || *history.ddgiSeenUpdate != scene.update.frame;
    for (std::size_t i = 0; i < scene.instances.size() && newUpdate; ++i) {
        const ecs::MeshId mesh = scene.instances[i].mesh;
        const auto listed = [&](const std::vector<ecs::MeshId>& v) {
            return std::find(v.begin(), v.end(), mesh) != v.end();
        };
        if (listed(scene.update.refitMeshes) || listed(scene.update.rebuiltMeshes)) volume.wakeProbes(bounds[i]);
    }
    const std::vector<Aabb>& before = history.ddgiInstanceBounds;
    for (std::size_t e = 0; e < std::max(now.size(), before.size()); ++e) {
        const Aabb a = e < before.size() ? before[e] : Aabb{}, b = e < now.size() ? now[e] : Aabb{};
        if (sameBox(a, b)) continue;
        volume.wakeProbes(a);
        volume.wakeProbes(b);
    }
    history.ddgiInstanceBounds = std::move(now);
    history.ddgiSeenUpdate = scene.update.frame;
}

}  // namespace

std::uint64_t runDdgiPass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    FrameHistory& history = passFrame.history;
    Image& out = passFrame.out.image;
    Image& atlas = passFrame.out.ddgiAtlas;
    DdgiUpdateStats& stats = passFrame.out.ddgi;
    std::vector<vec3> irradiance(ctx.gbuffer.size(), vec3(0.f));
    // Step: the probe volume (kept while the scene stays inside it).
    const std::vector<Aabb> perInstance = instanceBounds(ctx.scene);
    Aabb bounds;
    for (const Aabb& b : perInstance) bounds.extend(b);
    if (!history.ddgi || !contains(history.ddgi->bounds(), bounds)) {
        history.ddgi = std::make_shared<DdgiVolume>(bounds);
        history.ddgiInstanceBounds.clear();
    }
    DdgiVolume& volume = *history.ddgi;
    wakeAroundChanges(ctx.scene, perInstance, history, volume);
    const RayGrid grid{static_cast<int>(volume.raysPerProbe()), static_cast<int>(volume.probeCount())};
    const std::uint32_t frame = ctx.settings.frame, seed = ctx.settings.seed;

    // Step: probe rays, from the relocated positions of the probes
    // classification keeps (Idle and Inside probes trace nothing).
    std::vector<SecondaryRay> rays(grid.size());
    for (std::uint32_t probe = 0; probe < volume.probeCount(); ++probe)
        for (std::uint32_t r = 0; r < volume.raysPerProbe(); ++r) {
            SecondaryRay& ray = rays[std::size_t(probe) * volume.raysPerProbe() + r];
            ray.active = volume.probeTraced(probe);
            if (!ray.active) continue;
            // Unbounded: a ray that stops early would count as a miss (sky);
            // the volume clamps distances to maxRayDistance for the moments itself.
            ray.ray = tracer::RayDesc{volume.probePosition(probe), 0.f, volume.rayDirection(probe, r, frame, seed),
                                      kInfinity};
        }
    std::vector<HitPayload> hits;
    traceSecondary(ctx, grid, rays, kRayGi, hits, counters);

    // Step: shade the hits — emission, one light, and last frame's probes for further bounces.
    std::vector<vec3> incoming(grid.size()), weight(grid.size(), vec3(1.f)), radiance(grid.size(), vec3(0.f));
    const bool feedback = volume.updatesSinceReset() > 0;
    const auto seenFromFront = [&](const HitPayload& h) { return h.frontFace || ctx.material(h.material).doubleSided; };
    for (std::size_t i = 0; i < grid.size(); ++i) {
        incoming[i] = rays[i].ray.direction;
        const HitPayload& h = hits[i];
        if (!h.hit || !feedback || !seenFromFront(h)) continue;
        const ecs::Material& m = ctx.material(h.material);
        const vec3 diffuse =
            (1.f - glm::clamp(m.metallic, 0.f, 1.f)) * (1.f - glm::clamp(m.transmission, 0.f, 1.f)) * h.albedo;
        radiance[i] += diffuse / kPi * volume.irradiance(h.position, h.shadingNormal, -incoming[i]);
    }
    // Back-face hits only report a distance: no shading, no shadow rays.
    std::vector<HitPayload> shaded = hits;
    for (HitPayload& h : shaded)
        if (h.hit && !seenFromFront(h)) h.hit = false;
    shadeHits(ctx, grid, shaded, incoming, weight, 0, stream::kDdgiHit, radiance, counters);

    // Step: blend into the probes. Back faces of one-sided materials report a
    // negative distance (the paper's convention: the probe is inside geometry).
    std::vector<DdgiRayResult> results(grid.size());
    for (std::size_t i = 0; i < grid.size(); ++i) {
        const HitPayload& h = hits[i];
        results[i].radiance = radiance[i];
        results[i].distance = !h.hit ? kInfinity : (seenFromFront(h) ? h.t : -h.t);
    }
    volume.update(results, frame, seed);
    stats = volume.lastUpdateStats();

    // Step: irradiance at every surface.
    for (std::size_t i = 0; i < ctx.gbuffer.size(); ++i) {
        const GPixel& g = ctx.gbuffer[i];
        irradiance[i] = g.hit ? volume.irradiance(g.position, g.normal, g.viewDir) : vec3(0.f);
    }
    out.addRgbLayer("gi", irradiance);

    // Step: the irradiance atlas, for inspection.
    const DdgiAtlasImage e = volume.irradianceAtlasImage();
    atlas = Image(e.width, e.height);
    atlas.addRgbLayer("", e.texels);
    return volume.bytesAllocated() +
           grid.size() * (sizeof(SecondaryRay) + sizeof(HitPayload) + 3 * 3 * sizeof(float) + sizeof(DdgiRayResult));
}

}  // namespace rtlab::shaders::detail
