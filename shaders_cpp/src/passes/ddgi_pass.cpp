// DDGI (Majercik et al. 2019) as the GI technique: every frame each probe of
// the volume over the scene traces raysPerProbe rays (a rotated spherical
// Fibonacci set), their hits are shaded with emission + one light (shadow
// ray) + the previous probes' irradiance (multi-bounce feedback), the
// probes blend the results with hysteresis, and every G-buffer surface
// reads its irradiance with Chebyshev visibility and trilinear weights.
#include "indirect_shading.hpp"

#include <rtlab/shaders_cpp/ddgi.hpp>

namespace rtlab::shaders::detail {
namespace {

// World bounds of the instanced geometry.
Aabb instanceBounds(const ecs::SceneSnapshot& scene) {
    Aabb bounds;
    for (const ecs::InstanceSnapshot& inst : scene.instances)
        for (const ecs::Geometry& g : (*scene.meshes)[inst.mesh].geometries) {
            for (const vec3& p : g.positions) bounds.extend(vec3(inst.worldFromObject * vec4(p, 1.f)));
            for (const Aabb& b : g.proceduralBoxes)
                for (int c = 0; c < 8; ++c)
                    bounds.extend(vec3(inst.worldFromObject *
                                       vec4(c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z, 1.f)));
        }
    return bounds;
}

bool contains(const Aabb& outer, const Aabb& inner) {
    return glm::all(glm::lessThanEqual(outer.lo, inner.lo)) && glm::all(glm::greaterThanEqual(outer.hi, inner.hi));
}

}  // namespace

std::uint64_t runDdgiPass(RenderContext& ctx, FrameHistory& history, Image& out, std::vector<vec3>& irradiance,
                          Image& atlas, tracer::TraceCounters& counters) {
    // Step: the probe volume (kept while the scene stays inside it).
    const Aabb bounds = instanceBounds(ctx.scene);
    if (!history.ddgi || !contains(history.ddgi->bounds(), bounds)) history.ddgi = std::make_shared<DdgiVolume>(bounds);
    DdgiVolume& volume = *history.ddgi;
    const RayGrid grid{static_cast<int>(volume.raysPerProbe()), static_cast<int>(volume.probeCount())};
    const std::uint32_t frame = ctx.settings.frame, seed = ctx.settings.seed;

    // Step: probe rays.
    std::vector<SecondaryRay> rays(grid.size());
    for (std::uint32_t probe = 0; probe < volume.probeCount(); ++probe)
        for (std::uint32_t r = 0; r < volume.raysPerProbe(); ++r) {
            SecondaryRay& ray = rays[std::size_t(probe) * volume.raysPerProbe() + r];
            ray.active = true;
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
        const vec3 diffuse = (1.f - glm::clamp(m.metallic, 0.f, 1.f)) * (1.f - glm::clamp(m.transmission, 0.f, 1.f)) *
                             h.albedo;
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
    return volume.bytesAllocated() + grid.size() * (sizeof(SecondaryRay) + sizeof(HitPayload) + 3 * 3 * sizeof(float) +
                                                    sizeof(DdgiRayResult));
}

}  // namespace rtlab::shaders::detail
