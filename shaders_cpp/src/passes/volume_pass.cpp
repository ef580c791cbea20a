// Volumes: the fog's transmittance along every primary ray (to its surface,
// or through the fog for a miss) and single scattering from the lights: one
// distance sample per pixel and sample, uniform on the primary ray's segment
// inside each medium, lit by one importance-picked light through a shadow
// ray (itself attenuated by the fog). Isotropic phase function.
#include "indirect_shading.hpp"
#include "passes.hpp"

namespace rtlab::shaders::detail {

std::uint64_t runVolumePass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    if (ctx.media.empty()) return 0;  // planned, but no medium has density: nothing to trace
    Image& out = passFrame.out.image;
    const std::size_t n = ctx.gbuffer.size();
    std::vector<float> primaryTransmittance(n, 1.f);
    std::vector<vec3> inscatter(n, vec3(0.f));
    const int spp = ctx.settings.spp;
    const int w = ctx.width, h = ctx.height;
    std::vector<vec3> contribution(n, vec3(0.f)), sum(n, vec3(0.f));
    std::vector<float> tSum(n, 0.f);
    const PinholeCamera camera(ctx.scene.camera, w, h);
    for (int s = 0; s < spp; ++s) {
        counters.add(ctx.pipeline().dispatchCoherent(
            w, h,
            ctx.args(kRayShadow, tracer::RayFlag::AcceptFirstHitAndEndSearch | tracer::RayFlag::SkipClosestHitShader),
            [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
                const std::size_t i = ctx.pixelIndex(x, y);
                const GPixel& g = ctx.gbuffer[i];
                const CameraRay cam = camera.ray(x + 0.5f, y + 0.5f);
                const float tEnd = g.hit ? g.t : kInfinity;
                const std::uint32_t sample = static_cast<std::uint32_t>(s);
                // Step: the camera -> surface transmittance.
                tSum[i] += ctx.transmittance(cam.origin, cam.direction, tEnd, i, sample,
                                             stream::transmittance(stream::kVolumeScatter, 0));
                contribution[i] = vec3(0.f);
                // Step: one scattering point, uniform over the first medium's segment.
                const Medium& m = ctx.media.front();
                float t0, t1;
                if (!clipToBox(m.bounds, cam.origin, cam.direction, 0.f, tEnd, t0, t1)) return std::nullopt;
                const SampleKey key = ctx.key(i, sample, stream::kVolumeScatter);
                const float t = t0 + sampleUniform(key, 0) * (t1 - t0);
                const vec3 xs = cam.origin + t * cam.direction;
                const float sigmaT = extinction(m, xs);
                if (!(sigmaT > 0.f)) return std::nullopt;
                // Pick among all lights by unoriented importance (a medium has no normal).
                float pickPdf = 0.f;
                const ecs::LightSnapshot* light = pickByWeight(
                    ctx.scene.lights,
                    [&](const ecs::LightSnapshot& l) -> float {
                        if (!emits(l)) return 0.f;
                        if (l.light.type == ecs::LightType::Directional)
                            return luminance(l.light.color * l.light.intensity);
                        const vec3 d = vec3(l.worldFromLight[3]) - xs;
                        return luminance(l.light.color * l.light.intensity) / std::max(glm::dot(d, d), 1e-2f);
                    },
                    sampleUniform(key, 1), pickPdf);
                if (!light || !(pickPdf > 0.f)) return std::nullopt;
                const LightSample ls =
                    light->light.isArea()
                        ? sampleAreaLight(*light, xs, vec2(sampleUniform(key, 2), sampleUniform(key, 3)))
                        : pointLightSample(*light, xs);
                if (!ls.valid) return std::nullopt;
                const float camT = ctx.transmittance(cam.origin, cam.direction, t, i, sample,
                                                     stream::transmittance(stream::kVolumeScatter, 1));
                const float lightT = ctx.transmittance(xs, ls.direction, ls.distance, i, sample,
                                                       stream::transmittance(stream::kVolumeScatter, 2));
                const vec3 sigmaS = m.albedo * sigmaT;
                // L_s = sigma_s T_cam (1/4pi) Le/pdf T_light / p(t), p(t) = 1 / (t1 - t0).
                contribution[i] =
                    sigmaS * camT * (1.f / (4.f * kPi)) * ls.radianceOverPdf * lightT / pickPdf * (t1 - t0);
                if (!isFinite(contribution[i])) {
                    contribution[i] = vec3(0.f);
                    return std::nullopt;
                }
                return tracer::RayDesc{xs, 0.f, ls.direction, ls.distance};
            },
            [&](int x, int y, const HitPayload& p) {
                const std::size_t i = ctx.pixelIndex(x, y);
                if (p.missed) sum[i] += contribution[i];
            }));
    }
    float* T = out.addChannel("volume.transmittance", 1.f);
    for (std::size_t i = 0; i < n; ++i) {
        primaryTransmittance[i] = tSum[i] / float(spp);
        inscatter[i] = sum[i] / float(spp);
        T[i] = primaryTransmittance[i];
    }
    out.addRgbLayer("volume.inscatter", inscatter);
    return n * (3 * 3 * sizeof(float) + 2 * sizeof(float));
}

}  // namespace rtlab::shaders::detail
