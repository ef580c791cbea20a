// Reflections where roughness <= FramePlan::reflectionMaxRoughness (opaque
// materials): the mirror direction at roughness ~ 0, GGX visible-normal
// samples (Heitz 2018) otherwise; the hit is shaded with emission + every
// light (area lights by MIS of a light point and a specular-lobe sample,
// each with its shadow ray). Output: incoming radiance,
// hit distance, and the pre-integrated specular term (F0 x + y), so the
// denoiser filters radiance only and compose multiplies the term back.
#include "indirect_shading.hpp"
#include "passes.hpp"

#include <rtlab/core/parallel.hpp>

namespace rtlab::shaders::detail {

std::uint64_t runReflectionPass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    Image& out = passFrame.out.image;
    const std::size_t n = ctx.gbuffer.size();
    std::vector<vec3> specular(n, vec3(0.f));
    const int spp = ctx.settings.spp;
    SecondaryResult result(n);
    std::vector<std::uint32_t> validSamples(n, 0);  // samples that left above the surface
    std::vector<SecondaryRay> rays(n);
    std::vector<vec3> brdf(n, vec3(0.f));
    std::vector<std::uint8_t> glossy(n, 0);
    parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            const GPixel& g = ctx.gbuffer[i];
            glossy[i] =
                g.hit && g.roughness <= ctx.plan.reflectionMaxRoughness && ctx.material(g.material).transmission <= 0.f;
            if (!glossy[i]) continue;
            const vec2 ab = specularBrdfIntegral(std::max(glm::dot(g.normal, g.viewDir), 0.f), g.roughness);
            brdf[i] = specularF0(g.albedo, g.metalness) * ab.x + vec3(ab.y);
        }
    });
    for (int s = 0; s < spp; ++s) {
        parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) {
                rays[i].active = false;
                if (!glossy[i]) continue;
                const GPixel& g = ctx.gbuffer[i];
                const Frame frame = makeFrame(g.normal);
                const vec3 wo = toLocal(frame, g.viewDir);
                const GgxReflectionSample rs =
                    sampleGgxReflection(wo, ggxAlpha(g.roughness),
                                        ctx.screenStratified2D(i, static_cast<std::uint32_t>(s), stream::kReflection));
                if (!(rs.pdf > 0.f)) continue;
                const vec3 dir = glm::normalize(toWorld(frame, rs.wi));
                if (glm::dot(dir, g.geometricNormal) <= 0.f) continue;  // below the surface
                rays[i].active = true;
                ++validSamples[i];
                rays[i].ray = tracer::RayDesc{rayOriginLeaving(g.position, g.geometricNormal, dir, g.errorScale), 0.f,
                                              dir, kInfinity};
            }
        });
        // The reflected hit's direct light: every light with its own shadow
        // ray, not one picked (whose 1/pdf weight made the fireflies a sharp
        // mirror cannot filter away spatially); area lights by MIS of a light
        // point and a specular-lobe sample (a glossy hit's highlight of a
        // light larger than its lobe came as rare light points of huge f / pdf).
        traceAndShadeSecondary(ctx, rays, kRayReflection, static_cast<std::uint32_t>(s), stream::kReflectionHit, result,
                               counters, /*everyLight=*/true);
    }
    std::vector<vec3> radiance(n);
    float* hitT = out.addChannel("reflection.hitT", 0.f);
    parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            // Incoming radiance over the valid samples: the pre-integrated term already
            // accounts for the directions GGX sends below the horizon.
            radiance[i] = validSamples[i] ? result.radiance[i] / float(validSamples[i]) : vec3(0.f);
            hitT[i] = result.meanHitT(i);
            specular[i] = brdf[i] * radiance[i];
        }
    });
    out.addRgbLayer("reflection", radiance);
    out.addRgbLayer("reflection.brdf", brdf);
    return n * (sizeof(SecondaryRay) + sizeof(HitPayload) + sizeof(BrdfSample) + 6 * 3 * sizeof(float) +
                2 * sizeof(float) + 1);
}

}  // namespace rtlab::shaders::detail
