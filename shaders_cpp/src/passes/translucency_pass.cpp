// Translucency: a path from every transmissive G-buffer surface through
// dielectric interfaces — at each one it reflects with the Fresnel
// probability (always under total internal reflection) and refracts
// otherwise — with Beer-Lambert absorption inside (sigma_a = -ln(colour) /
// distance from the material's attenuation), until it meets an opaque
// surface (shaded with emission + one light and its shadow ray), leaves the
// scene, runs out of events (maxTranslucencyDepth) or its throughput falls
// below throughputCutoff.
#include "indirect_shading.hpp"
#include "passes.hpp"

#include <rtlab/core/parallel.hpp>

#include <cmath>

namespace rtlab::shaders::detail {
namespace {

// Unpolarised Fresnel reflectance of a dielectric interface; cosI > 0 on the
// incident side, eta = n_incident / n_transmitted. 1 under total internal reflection.
float fresnelDielectric(float cosI, float eta, float& cosT) {
    const float sin2T = eta * eta * std::max(0.f, 1.f - cosI * cosI);
    if (sin2T >= 1.f) {
        cosT = 0.f;
        return 1.f;
    }
    cosT = std::sqrt(1.f - sin2T);
    const float rs = (eta * cosI - cosT) / (eta * cosI + cosT);
    const float rp = (cosI - eta * cosT) / (cosI + eta * cosT);
    return glm::clamp(0.5f * (rs * rs + rp * rp), 0.f, 1.f);
}

vec3 absorptionCoefficient(const ecs::Material& m) {
    if (!(m.attenuationDistance > 0.f) || !std::isfinite(m.attenuationDistance)) return vec3(0.f);
    const vec3 c = glm::clamp(m.attenuationColor, vec3(1e-6f), vec3(1.f));
    return -glm::log(c) / m.attenuationDistance;
}

struct PathState {
    bool active = false;
    bool inside = false;  // travelling inside a transmissive medium
    vec3 throughput{1.f};
    vec3 sigmaA{0.f};  // absorption of the medium being travelled
};

// One interface event at `p` (normal n on the incident side, direction d):
// the next ray, and whether it crossed into/out of the medium.
tracer::RayDesc interfaceEvent(const vec3& p, const vec3& n, const vec3& d, float ior, bool entering, float u,
                               float errorScale, bool& crossed) {
    const float eta = entering ? 1.f / std::max(ior, 1e-3f) : std::max(ior, 1e-3f);
    const float cosI = glm::clamp(-glm::dot(d, n), 0.f, 1.f);
    float cosT = 0.f;
    const float F = fresnelDielectric(cosI, eta, cosT);
    vec3 next;
    if (u < F) {
        next = d + 2.f * cosI * n;  // reflect
        crossed = false;
    } else {
        next = eta * d + (eta * cosI - cosT) * n;  // refract
        crossed = true;
    }
    next = glm::normalize(next);
    return tracer::RayDesc{rayOriginLeaving(p, n, next, errorScale), 0.f, next, kInfinity};
}

}  // namespace

std::uint64_t runTranslucencyPass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    Image& out = passFrame.out.image;
    const std::size_t n = ctx.gbuffer.size();
    std::vector<vec3> transmitted(n, vec3(0.f));
    const int spp = ctx.settings.spp;
    const int maxDepth = ctx.settings.maxTranslucencyDepth;  // >= 1: RenderSettings::validate
    std::vector<PathState> state(n);
    std::vector<SecondaryRay> rays(n);
    std::vector<HitPayload> hits, finals(n);
    std::vector<vec3> incoming(n), weight(n), radiance(n, vec3(0.f));
    std::vector<float> firstT(n, 0.f);
    std::vector<std::uint32_t> firstHits(n, 0);
    for (int s = 0; s < spp; ++s) {
        // Step: the first interface, at the G-buffer surface.
        parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) {
                const GPixel& g = ctx.gbuffer[i];
                state[i] = PathState{};
                rays[i].active = false;
                finals[i] = HitPayload{};
                if (!g.hit || !(g.transmission > 0.f)) continue;
                const ecs::Material& m = ctx.material(g.material);
                const SampleKey key = ctx.key(i, static_cast<std::uint32_t>(s), stream::kTranslucency);
                bool crossed = false;
                rays[i].ray = interfaceEvent(g.position, g.geometricNormal, -g.viewDir, m.ior, g.frontFace,
                                             sampleUniform(key, 0), g.errorScale, crossed);
                rays[i].active = true;
                state[i].active = true;
                state[i].inside = crossed == g.frontFace;
                state[i].sigmaA = absorptionCoefficient(m);
                state[i].throughput = vec3(1.f);
            }
        });
        // Step: follow the paths, one event per dispatch.
        for (int depth = 1; depth <= maxDepth; ++depth) {
            traceSecondary(ctx, imageGrid(ctx), rays, kRayTranslucency, hits, counters);
            parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
                for (std::size_t i = begin; i < end; ++i) {
                    if (!rays[i].active) continue;
                    PathState& st = state[i];
                    const HitPayload& h = hits[i];
                    if (depth == 1 && h.hit) {
                        firstT[i] += h.t;
                        ++firstHits[i];
                    }
                    rays[i].active = false;
                    if (!h.hit) continue;  // left the scene: no environment light
                    if (st.inside) st.throughput *= glm::exp(-st.sigmaA * h.t);
                    const ecs::Material& m = ctx.material(h.material);
                    if (m.transmission > 0.f && depth < maxDepth &&
                        std::max({st.throughput.x, st.throughput.y, st.throughput.z}) >=
                            ctx.settings.throughputCutoff) {
                        const SampleKey key = ctx.key(i, static_cast<std::uint32_t>(s),
                                                      stream::kTranslucency + static_cast<std::uint32_t>(depth));
                        bool crossed = false;
                        rays[i].ray = interfaceEvent(h.position, h.geometricNormal, rays[i].ray.direction, m.ior,
                                                     h.frontFace, sampleUniform(key, 0), h.errorScale, crossed);
                        rays[i].active = true;
                        if (crossed) {
                            st.inside = h.frontFace;
                            st.sigmaA = absorptionCoefficient(m);
                        }
                    } else if (!(m.transmission > 0.f)) {
                        // An opaque surface ends the path: shaded below.
                        finals[i] = h;
                        incoming[i] = rays[i].ray.direction;
                        weight[i] = st.throughput;
                    }
                }
            });
        }
        shadeHits(ctx, imageGrid(ctx), finals, incoming, weight, static_cast<std::uint32_t>(s),
                  stream::kTranslucencyHit, radiance, counters);
    }
    float* hitT = out.addChannel("translucency.hitT", 0.f);
    parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            transmitted[i] = radiance[i] / float(spp);
            hitT[i] = firstHits[i] ? firstT[i] / float(firstHits[i]) : 0.f;
        }
    });
    out.addRgbLayer("translucency", transmitted);
    return n *
           (sizeof(PathState) + sizeof(SecondaryRay) + 2 * sizeof(HitPayload) + 4 * 3 * sizeof(float) + sizeof(float));
}

}  // namespace rtlab::shaders::detail
