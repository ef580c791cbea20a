#pragma once
// The passes (one file each in this folder), as the effect table
// (src/effect_table.cpp) runs them: each takes the frame's shared state,
// adds its layers to the frame's image and returns the bytes it allocated.
#include "../render_context.hpp"

#include <rtlab/shaders_cpp/frame_renderer.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace rtlab::shaders::detail {

// What one frame's passes share.
struct PassFrame {
    RenderContext& ctx;
    FrameHistory& history;  // the previous frame (read by the G-buffer's motion vectors) and the DDGI probes
    FrameOutput& out;       // the image's layers, the primary-ray order, DDGI's atlas and stats, path vertices
};

// Primary visibility and the guide buffers (gbuffer_pass.cpp); records the
// primary rays' pixel order when RenderSettings::recordRayOrder is set.
std::uint64_t runGBufferPass(PassFrame& passFrame, tracer::TraceCounters& counters);
// Each area light's unshadowed light and visibility, the point lights'
// shadowed light (shadow_pass.cpp).
std::uint64_t runShadowPass(PassFrame& passFrame, tracer::TraceCounters& counters);
// brdf x incoming radiance per pixel (reflection_pass.cpp).
std::uint64_t runReflectionPass(PassFrame& passFrame, tracer::TraceCounters& counters);
// The radiance arriving through (and reflected off) transmissive surfaces,
// Fresnel-weighted, per pixel (translucency_pass.cpp).
std::uint64_t runTranslucencyPass(PassFrame& passFrame, tracer::TraceCounters& counters);
// Cosine-hemisphere occlusion within RenderSettings::aoRadius (ao_pass.cpp).
std::uint64_t runAmbientOcclusionPass(PassFrame& passFrame, tracer::TraceCounters& counters);
// Diffuse GI by the plan's technique: one path bounce (gi_pass.cpp) or DDGI
// probes with hysteresis, kept in the history (ddgi_pass.cpp). Both write
// the irradiance (albedo demodulated) per pixel.
std::uint64_t runDiffuseGiPass(PassFrame& passFrame, tracer::TraceCounters& counters);
std::uint64_t runGlobalIlluminationPass(PassFrame& passFrame, tracer::TraceCounters& counters);
std::uint64_t runDdgiPass(PassFrame& passFrame, tracer::TraceCounters& counters);
// Primary-ray transmittance and single scattering of the fog volumes (volume_pass.cpp).
std::uint64_t runVolumePass(PassFrame& passFrame, tracer::TraceCounters& counters);
// --effects pathtrace: RenderSettings::pathMaxDepth bounces of diffuse +
// glossy paths from the G-buffer, next-event estimation at every vertex;
// writes the "pathtrace" layer (the whole estimate) and the rays per vertex
// (path_trace_pass.cpp).
std::uint64_t runPathTracePass(PassFrame& passFrame, tracer::TraceCounters& counters);

// AO contact sampling (RenderSettings::aoContactExtraSamples) looks this many
// pixels around a pixel (a 5x5 window).
inline constexpr int kAoContactWindow = 2;
// The contact samples per sample of each pixel: perSample for geometry
// pixels whose window holds another pixel with occluderDistance (the mean
// over its samples, +inf for none) below nearDistance, else 0; lowered where
// needed so that the counts sum to at most budgetPerPixel x the geometry
// pixels. A pixel's own samples never decide its count: a count that
// depended on them would bias its mean (more samples after a near hit would
// pull it down). Its neighbours' samples are independent of its own, and the
// budget's share is computed as if its own samples had seen no near
// occluder (the pixels that only it flags are taken off the flagged count,
// and the most it could flag added back). Throws std::invalid_argument when
// the buffers do not match width x height.
std::vector<std::uint32_t> aoContactSampleCounts(int width, int height, std::span<const float> occluderDistance,
                                                 std::span<const std::uint8_t> geometry, float nearDistance,
                                                 std::uint32_t perSample, std::size_t budgetPerPixel);

}  // namespace rtlab::shaders::detail
