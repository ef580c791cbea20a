#include "indirect_shading.hpp"

#include <rtlab/core/parallel.hpp>

#include <algorithm>

namespace rtlab::shaders::detail {

RayGrid imageGrid(const RenderContext& ctx) { return RayGrid{ctx.width, ctx.height}; }

void traceSecondary(RenderContext& ctx, const RayGrid& grid, const std::vector<SecondaryRay>& rays, RayType rayType,
                    std::vector<HitPayload>& hits, tracer::TraceCounters& counters) {
    reserveTouchedInParallel(hits, grid.size());
    hits.assign(grid.size(), HitPayload{});
    const auto index = [&](int x, int y) { return std::size_t(y) * std::size_t(grid.width) + std::size_t(x); };
    counters.add(ctx.pipeline().dispatchCoherent(
        grid.width, grid.height, ctx.args(rayType),
        [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
            const SecondaryRay& r = rays[index(x, y)];
            if (!r.active) return std::nullopt;
            return r.ray;
        },
        [&](int x, int y, const HitPayload& p) { hits[index(x, y)] = p; }, tracer::RayCoherence::Incoherent));
}

void shadeHits(RenderContext& ctx, const RayGrid& grid, const std::vector<HitPayload>& hits,
               const std::vector<vec3>& incoming, const std::vector<vec3>& weight, std::uint32_t sample,
               std::uint32_t hitStream, std::vector<vec3>& radiance, tracer::TraceCounters& counters, bool everyLight) {
    const std::size_t n = hits.size();
    std::vector<vec3> lightContribution = vectorTouchedInParallel(n, vec3(0.f));
    const auto index = [&](int x, int y) { return std::size_t(y) * std::size_t(grid.width) + std::size_t(x); };
    const auto args =
        ctx.args(kRayShadow, tracer::RayFlag::AcceptFirstHitAndEndSearch | tracer::RayFlag::SkipClosestHitShader);
    // A shadow query: the miss shader runs when nothing occludes (closest-hit is skipped).
    const auto unoccluded = [&](int x, int y, const HitPayload& p) {
        const std::size_t i = index(x, y);
        if (p.missed) radiance[i] += lightContribution[i];
    };
    // The shadow ray of one weighted light sample from hit i; its contribution
    // (path weight x f cos x Le / pdf x fog on fog segment `segment`) counts if unoccluded.
    const auto shadowed = [&](std::size_t i, const ShadingPoint& sp, const LightSample& ls,
                              std::uint32_t segment) -> std::optional<tracer::RayDesc> {
        const tracer::RayDesc ray = shadowRayToward(ls, sp.position, sp.geometricNormal, sp.errorScale);
        lightContribution[i] = weight[i] * evalBrdfCos(sp, ls.direction) * ls.radianceOverPdf *
                               ctx.transmittance(ray.origin, ray.direction, ray.tMax, i, sample,
                                                 stream::transmittance(hitStream, segment));
        if (!isFinite(lightContribution[i]) || lightContribution[i] == vec3(0.f)) return std::nullopt;
        return std::optional<tracer::RayDesc>(ray);
    };
    // One shadow ray per hit from `sampleFor(i, shading point)`, incoherent.
    const auto traceFromHits = [&](auto&& sampleFor) {
        counters.add(ctx.pipeline().dispatchCoherent(
            grid.width, grid.height, args,
            [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
                const std::size_t i = index(x, y);
                lightContribution[i] = vec3(0.f);
                const HitPayload& h = hits[i];
                if (!h.hit) return std::nullopt;
                return sampleFor(i, shadingPointOf(h, ctx.material(h.material), -incoming[i]));
            },
            unoccluded, tracer::RayCoherence::Incoherent));
    };
    // The specular-lobe sample of each hit (lobeSample), where its ray meets
    // area light `light` (lights are not geometry: each one the ray passes
    // through counts, behind its own shadow ray), weighted by MIS (power
    // heuristic) against the light's own strategy, whose pdf is
    // pickPdf(shading point) x the light's solid-angle pdf. Both weights use
    // specularLobePdf, so they are exact complements.
    std::vector<BrdfSample> lobeSample = vectorTouchedInParallel<BrdfSample>(n);
    const auto lobeMeetingLight = [&](const ecs::LightSnapshot& light, auto&& pickPdf) {
        traceFromHits([&](std::size_t i, const ShadingPoint& sp) -> std::optional<tracer::RayDesc> {
            const BrdfSample& b = lobeSample[i];
            if (!b.valid) return std::nullopt;
            const AreaLightHit lh = intersectAreaLight(light, sp.position, b.direction);
            if (!lh.valid) return std::nullopt;
            const float mis = powerHeuristic(1, specularLobePdf(sp, b.direction), 1, pickPdf(sp) * lh.pdf);
            if (!(mis > 0.f)) return std::nullopt;
            LightSample target;
            target.direction = b.direction;
            target.distance = lh.distance;
            target.radianceOverPdf = lh.radiance * (mis / b.pdf);
            return shadowed(i, sp, target, 2);
        });
    };
    if (everyLight) {
        // Every emitting light, no pick. A point, spot or directional light:
        // one shadow ray toward it. An area light: two strategies combined by
        // multiple importance sampling (Veach's power heuristic): a point on
        // the light (dimensions 3 + 2l, 4 + 2l of the key), and one sample of
        // the specular lobe per hit (GGX visible normals, dimensions 1, 2;
        // shared by the lights) that counts where its ray meets the light. A
        // glossy hit's highlight of a light larger than its lobe then comes
        // from the lobe's samples, not from rare light points of huge f / pdf
        // (nor from the rare pick of the specular lobe of the whole BRDF).
        parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) {
                if (!hits[i].hit) continue;
                radiance[i] += weight[i] * ctx.material(hits[i].material).emissive;
                const ShadingPoint sp = shadingPointOf(hits[i], ctx.material(hits[i].material), -incoming[i]);
                const SampleKey key = ctx.key(i, sample, hitStream);
                lobeSample[i] = sampleSpecularLobe(sp, vec2(sampleUniform(key, 1), sampleUniform(key, 2)));
            }
        });
        for (std::size_t l = 0; l < ctx.scene.lights.size(); ++l) {
            const ecs::LightSnapshot& light = ctx.scene.lights[l];
            if (!emits(light)) continue;
            const auto dim = static_cast<std::uint32_t>(3 + 2 * l);
            // Step: the light's own sample.
            traceFromHits([&](std::size_t i, const ShadingPoint& sp) -> std::optional<tracer::RayDesc> {
                const SampleKey key = ctx.key(i, sample, hitStream);
                const bool area = light.light.isArea();
                const LightSample ls = area
                                           ? sampleAreaLight(light, sp.position,
                                                             vec2(sampleUniform(key, dim), sampleUniform(key, dim + 1)))
                                           : pointLightSample(light, sp.position);
                if (!ls.valid || glm::dot(ls.direction, sp.geometricNormal) <= 0.f) return std::nullopt;
                const float mis = area ? powerHeuristic(1, ls.pdf, 1, specularLobePdf(sp, ls.direction)) : 1.f;
                if (!(mis > 0.f)) return std::nullopt;
                LightSample weighted = ls;
                weighted.radianceOverPdf *= mis;
                return shadowed(i, sp, weighted, 0);
            });
            if (!light.light.isArea()) continue;
            // Step: the specular-lobe sample, where its ray meets this light.
            lobeMeetingLight(light, [](const ShadingPoint&) { return 1.f; });
        }
        return;
    }
    // Step: emission at the hit, and one light picked by importance with its
    // shadow query. At a glossy hit (roughness in [kLobeMisFromRoughness,
    // kLobeMisBelowRoughness)) an area light's sample is weighted by MIS
    // against one specular-lobe sample (dimensions 3, 4), which counts where
    // its ray meets an area light (below): the light's highlight comes from
    // the lobe's samples, not from rare light points of huge f / pdf.
    const auto glossy = [&](const ShadingPoint& sp) {
        return sp.roughness >= kLobeMisFromRoughness && sp.roughness < kLobeMisBelowRoughness;
    };
    counters.add(ctx.pipeline().dispatchCoherent(
        grid.width, grid.height, args,
        [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
            const std::size_t i = index(x, y);
            const HitPayload& h = hits[i];
            lightContribution[i] = vec3(0.f);
            if (!h.hit) return std::nullopt;
            const ecs::Material& m = ctx.material(h.material);
            radiance[i] += weight[i] * m.emissive;
            const ShadingPoint sp = shadingPointOf(h, m, -incoming[i]);
            const SampleKey key = ctx.key(i, sample, hitStream);
            if (glossy(sp)) lobeSample[i] = sampleSpecularLobe(sp, vec2(sampleUniform(key, 3), sampleUniform(key, 4)));
            float pickPdf = 0.f;
            const ecs::LightSnapshot* light = pickLight(ctx.scene, sp, sampleUniform(key, 0), pickPdf);
            if (!light) return std::nullopt;
            const bool area = light->light.isArea();
            const LightSample ls =
                area ? sampleAreaLight(*light, sp.position, vec2(sampleUniform(key, 1), sampleUniform(key, 2)))
                     : pointLightSample(*light, sp.position);
            if (!ls.valid || glm::dot(ls.direction, sp.geometricNormal) <= 0.f) return std::nullopt;
            const float mis =
                area && glossy(sp) ? powerHeuristic(1, pickPdf * ls.pdf, 1, specularLobePdf(sp, ls.direction)) : 1.f;
            if (!(mis > 0.f)) return std::nullopt;
            LightSample weighted = ls;
            weighted.radianceOverPdf *= mis / pickPdf;
            return shadowed(i, sp, weighted, 0);
        },
        unoccluded, tracer::RayCoherence::Incoherent));
    // Step: the specular-lobe samples, one shadow dispatch per area light.
    if (std::none_of(lobeSample.begin(), lobeSample.end(), [](const BrdfSample& b) { return b.valid; })) return;
    for (const ecs::LightSnapshot& light : ctx.scene.lights)
        if (light.light.isArea() && emits(light))
            lobeMeetingLight(light, [&](const ShadingPoint& sp) { return lightPickPdf(ctx.scene, sp, light); });
}

void traceAndShadeSecondary(RenderContext& ctx, const std::vector<SecondaryRay>& rays, RayType rayType,
                            std::uint32_t sample, std::uint32_t hitStream, SecondaryResult& result,
                            tracer::TraceCounters& counters, bool everyLight) {
    std::vector<HitPayload> hits;
    const RayGrid grid = imageGrid(ctx);
    traceSecondary(ctx, grid, rays, rayType, hits, counters);
    std::vector<vec3> incoming(hits.size()), weight(hits.size(), vec3(1.f));
    parallelForChunks(hits.size(), kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            incoming[i] = rays[i].ray.direction;
            if (!hits[i].hit) continue;
            result.hitT[i] += hits[i].t;
            ++result.hits[i];
            // Fog between the surface and the secondary hit.
            weight[i] = vec3(ctx.transmittance(rays[i].ray.origin, rays[i].ray.direction, hits[i].t, i, sample,
                                               stream::transmittance(hitStream, 1)));
        }
    });
    shadeHits(ctx, grid, hits, incoming, weight, sample, hitStream, result.radiance, counters, everyLight);
}

}  // namespace rtlab::shaders::detail
