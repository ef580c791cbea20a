// Diffuse GI (one-bounce path): a cosine-distributed ray from every G-buffer
// surface, its hit shaded with emission + next-event estimation. Output:
// irradiance (albedo demodulated: E = pi L_in for cosine sampling) and hit
// distance.
#include "indirect_shading.hpp"
#include "passes.hpp"

#include <rtlab/core/parallel.hpp>

namespace rtlab::shaders::detail {

std::uint64_t runDiffuseGiPass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    return passFrame.ctx.plan.gi == GiTechnique::Ddgi ? runDdgiPass(passFrame, counters)
                                                      : runGlobalIlluminationPass(passFrame, counters);
}

std::uint64_t runGlobalIlluminationPass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    Image& out = passFrame.out.image;
    const std::size_t n = ctx.gbuffer.size();
    std::vector<vec3> irradiance(n, vec3(0.f));
    const int spp = ctx.settings.spp;
    SecondaryResult result(n);
    std::vector<SecondaryRay> rays(n);
    for (int s = 0; s < spp; ++s) {
        parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) {
                const GPixel& g = ctx.gbuffer[i];
                rays[i].active = g.hit;
                if (!g.hit) continue;
                const SampleKey key = ctx.key(i, static_cast<std::uint32_t>(s), stream::kGiBounce);
                const vec3 dir = cosineDirectionAbove(g.normal, g.geometricNormal,
                                                      vec2(sampleUniform(key, 0), sampleUniform(key, 1)));
                rays[i].ray = tracer::RayDesc{rayOriginLeaving(g.position, g.geometricNormal, dir, g.errorScale), 0.f,
                                              dir, kInfinity};
            }
        });
        traceAndShadeSecondary(ctx, rays, kRayGi, static_cast<std::uint32_t>(s), stream::kGiHit, result, counters);
    }
    float* hitT = out.addChannel("gi.hitT", 0.f);
    parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            irradiance[i] = kPi * result.radiance[i] / float(spp);
            hitT[i] = result.meanHitT(i);
        }
    });
    out.addRgbLayer("gi", irradiance);
    return n * (sizeof(SecondaryRay) + sizeof(HitPayload) + 4 * 3 * sizeof(float) + 2 * sizeof(float));
}

}  // namespace rtlab::shaders::detail
