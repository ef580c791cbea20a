#pragma once
// The frame renderer: the passes of a FramePlan as shader programs on the
// DXR pipeline (Embree or the RT-core model), each writing its noisy signal
// plus the guide buffers its denoiser needs, and a composed beauty image.
//
// Ray types (RayContributionToHitGroupIndex; per-type counters in stats):
//   0 primary (G-buffer), 1 shadow, 2 reflection, 3 ambient occlusion,
//   4 diffuse GI, 5 translucency, 6 path-trace bounce (--effects pathtrace;
//   its next-event rays are shadow rays, type 1)
// Random numbers: SampleKey{pixel, frame, sample, bounce, seed} (core/rng.hpp).
#include <rtlab/core/image.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/shaders_cpp/ddgi.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>
#include <vector>

namespace rtlab::shaders {

enum RayType : std::uint32_t {
    kRayPrimary = 0,
    kRayShadow = 1,
    kRayReflection = 2,
    kRayOcclusion = 3,
    kRayGi = 4,
    kRayTranslucency = 5,
    kRayPathBounce = 6,
    kRayTypeCount = 7,
};
// Stats names of the ray types: "primary", "shadow", "reflection", "ao", "gi", "translucency", "pathBounce".
std::string_view rayTypeName(std::uint32_t rayType);

struct RenderSettings {
    int width = 640;
    int height = 360;
    int spp = 1;              // samples per pixel per effect
    std::uint32_t frame = 0;  // frame index (random numbers, DDGI history)
    std::uint32_t seed = 0;
    tracer::TraversalBackend* backend = nullptr;  // nullptr = Embree
    bool recordRayOrder = false;                  // FrameOutput::primaryRayPixels (with a back end)
    float aoRadius = 1.0f;                        // world units
    // AO contact sampling: a pixel whose neighbourhood (5x5) saw an occluder
    // nearer than aoContactFraction x aoRadius gets this many more AO samples
    // per sample (0 = every pixel the same count). Contact creases are dark,
    // so their noise weighs most, and the denoiser's footprint there is small.
    int aoContactExtraSamples = 8;
    float aoContactFraction = 0.25f;
    int maxTranslucencyDepth = 8;           // refraction/reflection events along a translucent path
    float throughputCutoff = 1e-3f;         // a translucent path ends below this throughput
    float areaLightUnshadowedSamples = 16;  // samples of the unshadowed area-light estimate (no rays)
    int pathMaxDepth = 4;  // pathtrace: bounce rays after the primary hit (each with its next-event ray)

    // Throws std::invalid_argument unless width, height, spp and
    // maxTranslucencyDepth are >= 1 and pathMaxDepth >= 0 (renderFrame calls
    // it: the passes rely on it). Built from options, the settings come from
    // session::FrameSession, which validated those options first.
    void validate() const;
};

// What persists from frame to frame: the previous camera, instance
// transforms and deformed vertices (motion vectors) and the DDGI probes
// (hysteresis). renderFrame
// reads and then updates it.
struct FrameHistory {
    bool valid = false;
    ecs::CameraSnapshot camera;
    std::vector<mat4> worldFromObject;  // by entity index
    std::vector<bool> present;          // by entity index
    // Object-space vertex positions of deforming meshes (morph targets,
    // skinning) as they were, by mesh id then geometry; empty for rigid
    // meshes. Motion vectors interpolate the hit triangle's previous vertices.
    std::vector<std::vector<std::vector<vec3>>> deformedPositions;
    std::shared_ptr<DdgiVolume> ddgi;  // created by the first DDGI frame
    // DDGI probe classification follows the geometry (ddgi_pass.cpp): each
    // instance's world bounds at the last DDGI frame, by entity index (empty =
    // absent), and the World update that frame came from.
    std::vector<Aabb> ddgiInstanceBounds;
    std::optional<std::uint32_t> ddgiSeenUpdate;
    // Remembers `scene` as the previous frame of the next render.
    void record(const ecs::SceneSnapshot& scene);
};

// What one pass did this frame.
struct PassReport {
    std::uint64_t rays = 0;            // rays traced by the pass
    std::uint64_t bytesAllocated = 0;  // buffers the pass allocated
    double milliseconds = 0.0;         // wall time (not deterministic)
};

// The rays of one path vertex of the path tracer, summed over samples:
// vertex 0 is the primary hit (its next-event rays only), vertex d >= 1 is
// reached by the d-th bounce ray.
struct PathVertexRays {
    std::uint64_t bounceRays = 0;  // bounce rays traced to reach this vertex (0 at vertex 0)
    std::uint64_t bounceHits = 0;  // of those, how many hit a surface
    std::uint64_t shadowRays = 0;  // next-event (shadow) rays from this vertex
};

struct FrameOutput {
    Image image;  // beauty R,G,B + every pass's layers (docs/effects.md)
    std::array<PassReport, kPassCount> passes{};
    tracer::TraceCounters counters;               // summed over passes (per ray type)
    std::vector<std::uint32_t> primaryRayPixels;  // recordRayOrder: each primary thread's pixel (tilePixelOrder)
    std::uint64_t nonFiniteValuesRepaired = 0;    // NaN/Inf replaced by 0 before output (should stay 0)
    Image ddgiAtlas;       // --gi ddgi: the probes' irradiance atlas (R,G,B; DdgiVolume::irradianceAtlasImage)
    DdgiUpdateStats ddgi;  // --gi ddgi: the probe update's counters (probe states, rays, back faces)
    std::vector<PathVertexRays> pathVertices;  // --effects pathtrace: RenderSettings::pathMaxDepth + 1 entries
};

// The beauty image (R, G, B) from a frame's layers, the renderer's compose:
//   in-scattered + T x (emission + sum_i direct.light<i> x shadow.light<i>.V
//   + direct.point (or direct.pointPicked) + diffuse albedo / pi x gi + reflection.brdf x reflection
//   + transmission x translucency), or in-scattered + T x pathtrace when the
//   path tracer ran (its layer is the whole estimate), diffuse albedo = (1 - metalness)(1 -
//   transmission) albedo; sky pixels (id.mesh < 0) get the in-scattered light
//   only. Absent layers count as 0 (T as 1). Used again after denoising.
void composeBeauty(Image& frame);

// One effect's term of that compose, per pixel (what `rtlab converge`
// measures): shadows = sum_i direct.light<i> x shadow.light<i>.V +
// direct.point (or direct.pointPicked); reflections = reflection.brdf x reflection; ao = ao.V
// (grey); gi = diffuse albedo / pi x gi; translucency = transmission x
// translucency; volumes = volume.inscatter. 0 on sky pixels (except
// volumes). Throws std::invalid_argument for another name.
std::vector<vec3> effectContribution(const Image& frame, const std::string& effect);

// Renders one frame; `history` holds the previous frame (motion vectors,
// DDGI probes) and is updated to this one.
FrameOutput renderFrame(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene, const FramePlan& plan,
                        const RenderSettings& settings, FrameHistory& history);
// A single frame with no history.
FrameOutput renderFrame(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene, const FramePlan& plan,
                        const RenderSettings& settings);

}  // namespace rtlab::shaders
