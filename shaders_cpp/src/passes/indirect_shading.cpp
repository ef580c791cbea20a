#include "indirect_shading.hpp"

namespace rtlab::shaders::detail {

void traceAndShadeSecondary(RenderContext& ctx, const std::vector<SecondaryRay>& rays, RayType rayType,
                            std::uint32_t sample, std::uint32_t bounce, SecondaryResult& result,
                            tracer::TraceCounters& counters) {
    const std::size_t n = ctx.gbuffer.size();
    std::vector<HitPayload> hits(n);
    // Step: the secondary rays.
    counters.add(ctx.pipeline().dispatchCoherent(
        ctx.width, ctx.height, ctx.args(rayType),
        [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
            const SecondaryRay& r = rays[ctx.pixelIndex(x, y)];
            if (!r.active) return std::nullopt;
            return r.ray;
        },
        [&](int x, int y, const HitPayload& p) { hits[ctx.pixelIndex(x, y)] = p; }));

    // Step: emission at the hit, and one light picked by importance with its shadow ray.
    std::vector<vec3> lightContribution(n, vec3(0.f));
    counters.add(ctx.pipeline().dispatchCoherent(
        ctx.width, ctx.height, ctx.args(kRayShadow, tracer::RayFlag::AcceptFirstHitAndEndSearch | tracer::RayFlag::SkipClosestHitShader),
        [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
            const std::size_t i = ctx.pixelIndex(x, y);
            const HitPayload& h = hits[i];
            if (!rays[i].active || !h.hit) return std::nullopt;
            const ecs::Material& m = ctx.material(h.material);
            result.radiance[i] += m.emissive;
            result.hitT[i] += h.t;
            const ShadingPoint sp = shadingPointOf(h, m, -rays[i].ray.direction);
            const SampleKey key = ctx.key(i, sample, bounce);
            float pickPdf = 0.f;
            const ecs::LightSnapshot* light = pickLight(ctx.scene, sp, sampleUniform(key, 12), pickPdf);
            if (!light) return std::nullopt;
            const LightSample ls = light->light.isArea()
                                       ? sampleAreaLight(*light, sp.position,
                                                         vec2(sampleUniform(key, 13), sampleUniform(key, 14)))
                                       : pointLightSample(*light, sp.position);
            if (!ls.valid || glm::dot(ls.direction, sp.geometricNormal) <= 0.f) return std::nullopt;
            lightContribution[i] = evalBrdfCos(sp, ls.direction) * ls.radianceOverPdf / pickPdf;
            if (!isFinite(lightContribution[i])) return std::nullopt;
            return tracer::RayDesc{rayOriginLeaving(sp.position, sp.geometricNormal, ls.direction), 0.f, ls.direction,
                                   ls.distance};
        },
        // A shadow query: the miss shader runs when nothing occludes (closest-hit is skipped).
        [&](int x, int y, const HitPayload& p) {
            const std::size_t i = ctx.pixelIndex(x, y);
            if (p.missed) result.radiance[i] += lightContribution[i];
        }));
}

}  // namespace rtlab::shaders::detail
