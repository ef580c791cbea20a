// Shadows / direct light. Per area light: one visibility ray per pixel and
// sample toward a random point on the light -> visibility and occluder hit
// distance buffers (the shadow denoiser works per light), and the unshadowed
// light without rays (diffuse in closed form, specular by stratified
// samples). Point, spot and directional lights: a shadow ray to each (up to
// kTraceEveryPointLight of them), else one picked per pixel by importance.
#include "../lighting.hpp"
#include "passes.hpp"

#include <rtlab/core/parallel.hpp>

namespace rtlab::shaders::detail {

// Up to this many point / spot / directional lights each get a shadow ray
// per pixel (and per sample in fog, whose transmittance is sampled); more
// are sampled by an importance pick, per pixel and sample.
constexpr std::size_t kTraceEveryPointLight = 4;

std::uint64_t runShadowPass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    Image& out = passFrame.out.image;
    const std::size_t n = ctx.gbuffer.size();
    std::vector<vec3> direct(n, vec3(0.f));  // sum over lights of unshadowed x visibility
    const int spp = ctx.settings.spp;
    std::uint64_t bytes = 0;
    // Closest-hit queries: the occluder distance is the nearest one, the same on every back end.
    const tracer::TraceArgs shadowArgs = ctx.args(kRayShadow);
    const auto tracePerPixel = [&](auto&& makeRay, auto&& done) {
        counters.add(ctx.pipeline().dispatchCoherent(ctx.width, ctx.height, shadowArgs, makeRay, done));
    };

    // Step: area lights, one buffer set each.
    std::uint32_t areaIndex = 0;
    for (std::size_t li = 0; li < ctx.scene.lights.size(); ++li) {
        const ecs::LightSnapshot& light = ctx.scene.lights[li];
        if (!light.light.isArea() || !emits(light)) continue;
        const std::string layer = "shadow.light" + std::to_string(areaIndex);
        float* visibility = out.addChannel(layer + ".V", 1.f);
        float* hitT = out.addChannel(layer + ".hitT", 0.f);
        float* penumbra = out.addChannel(layer + ".penumbra", 0.f);
        std::vector<vec3> unshadowed(n, vec3(0.f));
        VisibilityTally tally(n);
        std::vector<float> mediumT(n, 1.f);       // this sample's fog transmittance toward the light
        std::vector<float> sampleWeight(n, 0.f);  // this sample's luminance(f cos Le / pdf): weights its visibility
        bytes += n * (3 * sizeof(float) + 3 * sizeof(float) + sizeof(float)) + tally.bytes();
        const std::uint32_t areaStream = stream::kAreaLight + areaIndex;
        for (int s = 0; s < spp; ++s) {
            tracePerPixel(
                [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
                    const std::size_t i = ctx.pixelIndex(x, y);
                    const GPixel& g = ctx.gbuffer[i];
                    if (!g.hit) return std::nullopt;
                    const LightSample ls = sampleAreaLight(
                        light, g.position, ctx.screenStratified2D(i, static_cast<std::uint32_t>(s), areaStream));
                    if (!ls.valid || glm::dot(ls.direction, g.geometricNormal) <= 0.f) return std::nullopt;
                    sampleWeight[i] = luminance(evalBrdfCos(shadingPointOf(g), ls.direction) * ls.radianceOverPdf);
                    if (!(sampleWeight[i] > 0.f) || !std::isfinite(sampleWeight[i])) return std::nullopt;
                    ++tally.tested[i];
                    const tracer::RayDesc ray = shadowRayToward(ls, g.position, g.geometricNormal, g.errorScale);
                    mediumT[i] = ctx.transmittance(ray.origin, ray.direction, ray.tMax, i,
                                                   static_cast<std::uint32_t>(s), stream::transmittance(areaStream));
                    return ray;
                },
                [&](int x, int y, const HitPayload& p) {
                    const std::size_t i = ctx.pixelIndex(x, y);
                    // Visibility weighted by each sample's contribution (so that unshadowed x
                    // visibility converges to the shadowed integral); fog attenuates what gets through.
                    tally.record(i, p, mediumT[i], sampleWeight[i]);
                });
        }
        // Step: per pixel, in parallel by rows (each pixel writes only its own
        // entries): the unshadowed estimate is most of this pass's work without rays.
        parallelForEach(static_cast<std::size_t>(ctx.height), [&](std::size_t row) {
            const std::size_t width = static_cast<std::size_t>(ctx.width);
            for (std::size_t i = row * width, end = i + width; i < end; ++i) {
                const GPixel& g = ctx.gbuffer[i];
                if (!g.hit) continue;
                visibility[i] = tally.visibility(i);
                hitT[i] = tally.meanOccluderDistance(i, 0.f);
                penumbra[i] = penumbraWidth(light, g.position, hitT[i]);
                unshadowed[i] = unshadowedAreaLight(light, shadingPointOf(g),
                                                    static_cast<int>(ctx.settings.areaLightUnshadowedSamples),
                                                    ctx.key(i, 0, areaStream), 2);
                direct[i] += unshadowed[i] * visibility[i];
            }
        });
        out.addRgbLayer("direct.light" + std::to_string(areaIndex), unshadowed);
        ++areaIndex;
    }

    // Step: point / spot / directional lights. A point light's visibility from
    // a pixel's G-buffer point has no noise, so with few of them each gets
    // its own shadow ray (the layer is then noise-free but for fog); with
    // more, one is picked per pixel by importance.
    std::vector<const ecs::LightSnapshot*> pointLights;
    for (const ecs::LightSnapshot& l : ctx.scene.lights)
        if (!l.light.isArea() && emits(l)) pointLights.push_back(&l);
    if (!pointLights.empty()) {
        std::vector<vec3> pointDirect(n, vec3(0.f)), contribution(n, vec3(0.f));
        bytes += n * 2 * 3 * sizeof(float);
        const auto addIfVisible = [&](int x, int y, const HitPayload& p) {
            const std::size_t i = ctx.pixelIndex(x, y);
            if (!p.hit) pointDirect[i] += contribution[i];
        };
        // One shadow ray from pixel i toward `light`; the contribution is divided by
        // the light's pick probability `pdf` (1 when every light is traced).
        const auto towardLight = [&](std::size_t i, const GPixel& g, const ShadingPoint& sp,
                                     const ecs::LightSnapshot& light, float pdf, int s,
                                     std::uint32_t fogStream) -> std::optional<tracer::RayDesc> {
            const LightSample ls = pointLightSample(light, g.position);
            if (!ls.valid) return std::nullopt;
            const vec3 f = evalBrdfCos(sp, ls.direction) * ls.radianceOverPdf / pdf;
            if (!(luminance(f) > 0.f)) return std::nullopt;
            const tracer::RayDesc ray = shadowRayToward(ls, g.position, g.geometricNormal, g.errorScale);
            contribution[i] =
                f * ctx.transmittance(ray.origin, ray.direction, ray.tMax, i, static_cast<std::uint32_t>(s), fogStream);
            return ray;
        };
        const bool traceEach = pointLights.size() <= kTraceEveryPointLight;
        // Traced one by one without fog, every sample's ray is the same: trace it once.
        const int samples = traceEach && ctx.media.empty() ? 1 : spp;
        for (std::uint32_t j = 0; j < (traceEach ? pointLights.size() : 1); ++j)
            for (int s = 0; s < samples; ++s)
                tracePerPixel(
                    [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
                        const std::size_t i = ctx.pixelIndex(x, y);
                        const GPixel& g = ctx.gbuffer[i];
                        contribution[i] = vec3(0.f);
                        if (!g.hit) return std::nullopt;
                        const ShadingPoint sp = shadingPointOf(g);
                        if (traceEach)
                            return towardLight(i, g, sp, *pointLights[j], 1.f, s,
                                               stream::transmittance(stream::kPointLightPick + 1 + j));
                        // Step: pick among the non-area lights by pointLightImportance.
                        const SampleKey key = ctx.key(i, static_cast<std::uint32_t>(s), stream::kPointLightPick);
                        float pdf = 0.f;
                        const ecs::LightSnapshot* chosen = pickByWeight(
                            ctx.scene.lights,
                            [&](const ecs::LightSnapshot& l) {
                                return !l.light.isArea() && emits(l) ? pointLightImportance(l, sp) : 0.f;
                            },
                            sampleUniform(key, 0), pdf);
                        if (!chosen) return std::nullopt;
                        return towardLight(i, g, sp, *chosen, pdf, s, stream::transmittance(stream::kPointLightPick));
                    },
                    addIfVisible);
        parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) {
                pointDirect[i] /= float(samples);
                direct[i] += pointDirect[i];
            }
        });
        // Traced one by one the layer has no noise but the fog's; picked, it is noisy
        // (the denoiser filters direct.pointPicked only).
        out.addRgbLayer(pointLights.size() <= kTraceEveryPointLight ? "direct.point" : "direct.pointPicked",
                        pointDirect);
    }
    return bytes;
}

}  // namespace rtlab::shaders::detail
