// Ambient occlusion: cosine-hemisphere rays around the shading normal,
// limited to RenderSettings::aoRadius; visibility and the nearest occluder's
// distance (a closest-hit query, so the distance is the same on every back
// end; a first-hit query would report whichever occluder traversal met first).
#include "../lighting.hpp"

namespace rtlab::shaders::detail {

std::uint64_t runAmbientOcclusionPass(RenderContext& ctx, Image& out, tracer::TraceCounters& counters) {
    const std::size_t n = ctx.gbuffer.size();
    const int spp = std::max(ctx.settings.spp, 1);
    const float radius = ctx.settings.aoRadius;
    float* visibility = out.addChannel("ao.V", 1.f);
    float* hitT = out.addChannel("ao.hitT", 0.f);
    VisibilityTally tally(n);
    for (int s = 0; s < spp; ++s)
        counters.add(ctx.pipeline().dispatchCoherent(
            ctx.width, ctx.height, ctx.args(kRayOcclusion),
            [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
                const std::size_t i = ctx.pixelIndex(x, y);
                const GPixel& g = ctx.gbuffer[i];
                if (!g.hit || !(radius > 0.f)) return std::nullopt;
                const SampleKey key = ctx.key(i, static_cast<std::uint32_t>(s), stream::kAmbientOcclusion);
                const vec3 dir = cosineDirectionAbove(g.normal, g.geometricNormal,
                                                      vec2(sampleUniform(key, 0), sampleUniform(key, 1)));
                ++tally.tested[i];
                return tracer::RayDesc{rayOriginLeaving(g.position, g.geometricNormal, dir, g.errorScale), 0.f, dir, radius};
            },
            [&](int x, int y, const HitPayload& p) { tally.record(ctx.pixelIndex(x, y), p); },
            tracer::RayCoherence::Incoherent));
    for (std::size_t i = 0; i < n; ++i) {
        if (!tally.tested[i]) continue;
        visibility[i] = tally.visibility(i);
        hitT[i] = tally.meanOccluderDistance(i, radius);
    }
    return n * 2 * sizeof(float) + tally.bytes();
}

}  // namespace rtlab::shaders::detail
