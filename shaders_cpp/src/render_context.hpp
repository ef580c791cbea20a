#pragma once
// Shared state of one frame's passes (internal to shaders_cpp): the pipeline
// with its shader table, the payload every hit group fills, the G-buffer the
// secondary passes start from, and small helpers.
#include "participating_media.hpp"

#include <rtlab/core/rng.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>

#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace rtlab::shaders::detail {

// Random-number streams. SampleKey::bounce carries the stream, so no two uses
// in a frame share random numbers; dimensions restart at 0 in each stream.
namespace stream {
inline constexpr std::uint32_t kAreaLight = 0x100;  // + area-light index: light point (0, 1), unshadowed jitter (2, 3)
inline constexpr std::uint32_t kPointLightPick =
    0x200;  // importance pick among point lights (0); + 1 + j: point light j when every one is traced
inline constexpr std::uint32_t kAmbientOcclusion = 0x300;  // direction (0, 1)
inline constexpr std::uint32_t kGiBounce = 0x400;          // direction (0, 1)
inline constexpr std::uint32_t kGiHit = 0x410;       // light pick and point at the GI hit (0, 1, 2), glossy lobe (3, 4)
inline constexpr std::uint32_t kReflection = 0x500;  // visible normal (0, 1)
inline constexpr std::uint32_t kReflectionHit =
    0x510;  // at the reflection hit: specular-lobe direction (1, 2), light l's point (3 + 2l, 4 + 2l)
inline constexpr std::uint32_t kTranslucency = 0x600;     // + event depth: Fresnel choice (0)
inline constexpr std::uint32_t kTranslucencyHit = 0x6ff;  // light at the opaque end (0, 1, 2), glossy lobe (3, 4)
inline constexpr std::uint32_t kVolumeScatter = 0x700;    // distance, light pick, light point (0 .. 3)
inline constexpr std::uint32_t kDdgiHit = 0x800;          // light at a probe ray's hit (0, 1, 2), glossy lobe (3, 4)
inline constexpr std::uint32_t kPathBounce = 0x900;       // + path vertex: lobe choice (0), direction (1, 2)
inline constexpr std::uint32_t kPathHit =
    0xa00;  // + path vertex: light pick and point there (0, 1, 2), glossy lobe (3, 4)
// Fog transmittance along a ray of stream s: kTransmittance + 4 s + segment (dimensions 0 .. 255);
// at hits: 0 the light's shadow ray, 1 the ray to the hit, 2 the lobe sample's shadow ray.
inline constexpr std::uint32_t kTransmittance = 0x10000;
constexpr std::uint32_t transmittance(std::uint32_t s, std::uint32_t segment = 0) {
    return kTransmittance + 4 * s + segment;
}
}  // namespace stream

// What closest-hit reports: the surface at the committed hit (radiance-like
// ray types) or only the distance (shadow / occlusion rays).
struct HitPayload {
    bool hit = false;
    bool missed = false;  // the miss shader ran (tells a shadow query's miss from its skipped closest-hit)
    float t = 0.f;
    std::uint32_t instance = 0;
    std::uint32_t mesh = 0;
    std::uint32_t entity = 0;     // entity index of the instance
    std::uint32_t geometry = 0;   // geometry index in the mesh
    std::uint32_t primitive = 0;  // triangle index in the geometry
    vec2 barycentrics{0.f};       // of the hit in that triangle (DXR: weights of vertices 1 and 2)
    vec3 position{0.f};
    vec3 geometricNormal{0.f};  // unit, facing the incoming ray
    vec3 shadingNormal{0.f};    // unit, on the geometric normal's side
    bool frontFace = true;      // the ray hit the side the geometric normal points to
    vec2 uv{0.f};
    std::uint32_t material = 0;
    vec3 albedo{0.f};        // base colour at the hit (texture applied)
    float errorScale = 0.f;  // max |coordinate| of the ray origin and the hit (offsetRayOriginByError)
};

using RtPipeline = tracer::Pipeline<HitPayload>;

// One pixel of the G-buffer.
struct GPixel {
    bool hit = false;
    float depth = 0.f;  // linear view z (distance along the camera's forward axis)
    float t = 0.f;      // primary hit distance
    vec3 position{0.f};
    vec3 viewDir{0.f};          // unit, from the surface toward the camera
    vec3 normal{0.f};           // shading normal, facing the viewer
    vec3 geometricNormal{0.f};  // facing the viewer
    vec3 albedo{0.f};
    vec3 emissive{0.f};
    float roughness = 1.f;
    float metalness = 0.f;
    float transmission = 0.f;  // the material's transmission (0 opaque, 1 clear glass)
    bool frontFace = true;     // the primary ray hit the side the geometric normal points to (entering)
    std::uint32_t material = 0;
    std::uint32_t mesh = 0;
    std::uint32_t instance = 0;
    vec2 motion{0.f};        // pixels: previous position - current position
    float pixelWorld = 0.f;  // world-space width of the pixel at the hit (t x angle between neighbour rays)
    float errorScale = 0.f;  // max |coordinate| of the camera and the hit (offsetRayOriginByError)
};

class RenderContext {
public:
    RenderContext(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene, const FramePlan& plan,
                  const RenderSettings& settings);

    const tracer::AccelManager& accel;
    const ecs::SceneSnapshot& scene;
    const FramePlan& plan;
    const RenderSettings& settings;
    int width, height;
    std::vector<GPixel> gbuffer;  // first written in parallel (a frame's largest buffer)
    std::vector<Medium> media;    // filled only when the plan has the volumes pass

    // Transmittance of the media along (o, d) over [0, tMax] (1 without media);
    // streamId from stream::transmittance(...).
    float transmittance(const vec3& o, const vec3& d, float tMax, std::size_t pixel, std::uint32_t sample,
                        std::uint32_t streamId) const {
        return media.empty() ? 1.f : detail::transmittance(media, o, d, tMax, key(pixel, sample, streamId), 0);
    }

    const RtPipeline& pipeline() const { return *pipeline_; }
    // TraceRay arguments of a ray type: FORCE_OPAQUE unless the alpha pass is planned.
    tracer::TraceArgs args(RayType type, std::uint32_t extraFlags = 0) const;
    const ecs::Material& material(std::uint32_t id) const;
    std::size_t pixelIndex(int x, int y) const { return std::size_t(y) * std::size_t(width) + std::size_t(x); }
    // The random numbers of `pixel` (or ray-grid element), sample and stream (namespace stream).
    SampleKey key(std::size_t pixel, std::uint32_t sample, std::uint32_t streamId) const {
        return SampleKey{static_cast<std::uint32_t>(pixel), settings.frame, sample, streamId, settings.seed};
    }
    // The first 2D decision of sample `sample` (< settings.spp) of `pixel`
    // in `streamId`, stratified over the screen and within the pixel
    // (sampleScreenStratified2D): for a pass's one 2D choice per pixel and
    // sample at the primary hit, whose errors a spatial filter then averages.
    vec2 screenStratified2D(std::size_t pixel, std::uint32_t sample, std::uint32_t streamId) const {
        const std::size_t w = static_cast<std::size_t>(width > 0 ? width : 1);
        return sampleScreenStratified2D(static_cast<std::uint32_t>(pixel % w), static_cast<std::uint32_t>(pixel / w),
                                        sample, static_cast<std::uint32_t>(settings.spp), key(pixel, sample, streamId),
                                        0);
    }

private:
    std::unique_ptr<RtPipeline> pipeline_;
};

// Per-pixel sums of one pass's visibility rays (shadows, AO): how many were
// traced, how much got through (weighted, e.g. by fog transmittance), and
// the occluders' distances.
struct VisibilityTally {
    explicit VisibilityTally(std::size_t n)
        : visible(n, 0.f), weightSum(n, 0.f), occluderSum(n, 0.f), tested(n, 0), occluded(n, 0) {}
    std::vector<float> visible, weightSum, occluderSum;
    std::vector<std::uint32_t> tested, occluded;
    // One traced ray of pixel i with weight w: a hit occludes (closest-hit
    // query: p.t is the nearest occluder), a miss lets `throughput` through.
    void record(std::size_t i, const HitPayload& p, float throughput = 1.f, float w = 1.f) {
        weightSum[i] += w;
        if (p.hit) {
            ++occluded[i];
            occluderSum[i] += p.t;
        } else {
            visible[i] += w * throughput;
        }
    }
    // Weighted fraction that got through; 1 when nothing was traced.
    float visibility(std::size_t i) const { return weightSum[i] > 0.f ? visible[i] / weightSum[i] : 1.f; }
    float meanOccluderDistance(std::size_t i, float none) const {
        return occluded[i] ? occluderSum[i] / float(occluded[i]) : none;
    }
    std::uint64_t bytes() const { return visible.size() * (3 * sizeof(float) + 2 * sizeof(std::uint32_t)); }
};

// A cosine-distributed direction around the shading normal n, mirrored
// above the geometric normal ng when a bent shading normal sends it below.
vec3 cosineDirectionAbove(const vec3& n, const vec3& ng, vec2 u);

// Robust ray start on a surface (after Wächter & Binder, RT Gems ch. 6; see
// offsetRayOriginByError): offset along the geometric normal toward the side
// the ray leaves on, by a few ulps of `errorScale`.
vec3 rayOriginLeaving(const vec3& position, const vec3& geometricNormal, const vec3& direction, float errorScale);
// max |coordinate| of two points (a hit and the origin of the ray that found it).
float errorScaleOf(const vec3& a, const vec3& b);

}  // namespace rtlab::shaders::detail
