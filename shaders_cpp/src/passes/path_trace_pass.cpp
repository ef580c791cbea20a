// Path tracing (--effects pathtrace): the incoherent multi-bounce ray mix a
// hardware study wants, shaded well enough to look right. Wavefront style,
// one dispatch per bounce over the image grid:
//   vertex 0 = the G-buffer hit; at every vertex, emission + one light picked
//   by importance with its shadow ray (shadeHits, next-event estimation);
//   then a bounce: the diffuse or the GGX lobe picked by their estimated
//   weights, the direction sampled from it, weighted by f cos / (mixture pdf).
// Lights are reached by next-event estimation only (as in every pass: area
// lights are not geometry), emissive surfaces by bounce rays only, so no
// light is counted twice. Transmissive materials act as their opaque part
// (no refraction along paths), fog weights every segment by transmittance.
// Paths end after RenderSettings::pathMaxDepth bounces, on a miss, below the
// surface, or on a zero or non-finite weight (no Russian roulette, so the ray
// counts per vertex do not depend on random termination beyond misses).
#include "indirect_shading.hpp"
#include "passes.hpp"

#include <rtlab/core/parallel.hpp>

#include <algorithm>

namespace rtlab::shaders::detail {
namespace {

// The G-buffer pixel as a hit payload, so vertex 0 is shaded like the rest.
HitPayload payloadOf(const GPixel& g) {
    HitPayload p;
    p.hit = g.hit;
    p.t = g.t;
    p.instance = g.instance;
    p.mesh = g.mesh;
    p.position = g.position;
    p.geometricNormal = g.geometricNormal;
    p.shadingNormal = g.normal;
    p.frontFace = g.frontFace;
    p.material = g.material;
    p.albedo = g.albedo;
    p.errorScale = g.errorScale;
    return p;
}

// A bounce from a surface: direction and f cos / pdf, or nothing (the path ends).
struct BounceSample {
    vec3 direction{0.f};
    vec3 weight{0.f};
};

std::optional<BounceSample> sampleBounce(const ShadingPoint& sp, float uLobe, vec2 u) {
    const BrdfSample b = sampleBrdf(sp, uLobe, u);
    if (!b.valid) return std::nullopt;
    const vec3 weight = evalBrdfCos(sp, b.direction) / b.pdf;
    if (!isFinite(weight) || !(std::max({weight.x, weight.y, weight.z}) > 0.f)) return std::nullopt;
    return BounceSample{b.direction, weight};
}

}  // namespace

std::uint64_t runPathTracePass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    Image& out = passFrame.out.image;
    std::vector<PathVertexRays>& vertices = passFrame.out.pathVertices;
    const std::size_t n = ctx.gbuffer.size();
    const int spp = ctx.settings.spp;
    const int maxDepth = ctx.settings.pathMaxDepth;  // >= 0: RenderSettings::validate
    const RayGrid grid = imageGrid(ctx);
    vertices.assign(std::size_t(maxDepth) + 1, PathVertexRays{});
    // Step: the path state, a few hundred MB at 1080p, first written on every host thread.
    std::vector<vec3> radiance = vectorTouchedInParallel(n, vec3(0.f)), throughput = vectorTouchedInParallel<vec3>(n),
                      incoming = vectorTouchedInParallel<vec3>(n);
    std::vector<HitPayload> hits = vectorTouchedInParallel<HitPayload>(n);
    std::vector<SecondaryRay> rays = vectorTouchedInParallel<SecondaryRay>(n);
    for (int s = 0; s < spp; ++s) {
        const auto sample = static_cast<std::uint32_t>(s);
        parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i < end; ++i) {
                hits[i] = payloadOf(ctx.gbuffer[i]);
                incoming[i] = -ctx.gbuffer[i].viewDir;
                throughput[i] = vec3(1.f);
            }
        });
        for (int depth = 0;; ++depth) {
            const auto vertex = static_cast<std::uint32_t>(depth);
            // Step: emission and next-event estimation at this vertex.
            tracer::TraceCounters shade;
            shadeHits(ctx, grid, hits, incoming, throughput, sample, stream::kPathHit + vertex, radiance, shade);
            vertices[depth].shadowRays += shade.totalRays();
            counters.add(shade);
            if (depth == maxDepth) break;
            // Step: the bounce rays leaving every live vertex.
            parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
                for (std::size_t i = begin; i < end; ++i) {
                    rays[i].active = false;
                    if (!hits[i].hit) continue;
                    const ShadingPoint sp = shadingPointOf(hits[i], ctx.material(hits[i].material), -incoming[i]);
                    const SampleKey key = ctx.key(i, sample, stream::kPathBounce + vertex);
                    const std::optional<BounceSample> b =
                        sampleBounce(sp, sampleUniform(key, 0), vec2(sampleUniform(key, 1), sampleUniform(key, 2)));
                    if (!b) continue;
                    throughput[i] *= b->weight;
                    incoming[i] = b->direction;
                    rays[i].active = true;
                    rays[i].ray =
                        tracer::RayDesc{rayOriginLeaving(sp.position, sp.geometricNormal, b->direction, sp.errorScale),
                                        0.f, b->direction, kInfinity};
                }
            });
            if (std::none_of(rays.begin(), rays.end(), [](const SecondaryRay& r) { return r.active; })) break;
            tracer::TraceCounters bounce;
            traceSecondary(ctx, grid, rays, kRayPathBounce, hits, bounce);
            vertices[depth + 1].bounceRays += bounce.rays[kRayPathBounce];
            vertices[depth + 1].bounceHits += bounce.hits[kRayPathBounce];
            counters.add(bounce);
            // Step: fog between the vertices.
            parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
                for (std::size_t i = begin; i < end; ++i)
                    if (hits[i].hit)
                        throughput[i] *= ctx.transmittance(rays[i].ray.origin, rays[i].ray.direction, hits[i].t, i,
                                                           sample, stream::transmittance(stream::kPathBounce + vertex));
            });
        }
    }
    for (vec3& r : radiance) r /= float(spp);
    out.addRgbLayer("pathtrace", radiance);
    return n * (4 * 3 * sizeof(float) + sizeof(HitPayload) + sizeof(SecondaryRay));
}

}  // namespace rtlab::shaders::detail
