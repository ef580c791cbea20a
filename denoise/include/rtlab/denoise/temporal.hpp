#pragma once
// Temporal accumulation of colour and luminance moments with a per-pixel
// history length (SVGF, Schied et al. 2017, sections 4.1-4.2).
#include <rtlab/denoise/reprojection.hpp>

#include <span>
#include <vector>

namespace rtlab::denoise {

struct TemporalParams {
    // Minimum blend weight of the new sample for colour: alpha = max(alpha, 1/history).
    // Source: paper (0.2). Falcor's SVGFPass default is 0.05.
    float alpha = 0.2f;
    // Same for the luminance moments. Source: paper and Falcor (0.2).
    float momentsAlpha = 0.2f;
    // History length saturates here. Source: Falcor (32); the paper sets no cap
    // (alpha's floor makes lengths beyond 1/alpha irrelevant to the blend).
    float maxHistoryLength = 32.f;
};

// The per-pixel state carried from frame to frame.
struct HistoryBuffers {
    int width = 0;
    int height = 0;
    std::vector<vec3> color;             // accumulated (demodulated) colour
    std::vector<vec2> moments;           // accumulated luminance moments (E[l], E[l^2])
    std::vector<float> length;           // history length in frames; 0 = no history
    void resize(int width, int height);  // zero-filled
    std::size_t pixelCount() const { return static_cast<std::size_t>(width) * static_cast<std::size_t>(height); }
};

// Gathers the previous frame's history through `r` into `out` (resized):
// invalid pixels get colour 0, moments 0, length 0.
void reprojectHistory(const Reprojection& r, const HistoryBuffers& previous, HistoryBuffers& out);

// One step of accumulation, per pixel:
//   reprojected.length > 0: length = min(reprojected.length + 1, maxHistoryLength),
//                           a = max(alpha, 1/length), am = max(momentsAlpha, 1/length);
//   otherwise (disocclusion): length = 1, a = am = 1.
//   color   = mix(reprojected.color,   sample,               a)
//   moments = mix(reprojected.moments, luminanceMoments(sample), am)
// `out` is resized; it may be the same object as `reprojected`.
void accumulateTemporal(std::span<const vec3> color, const HistoryBuffers& reprojected, const TemporalParams& params,
                        HistoryBuffers& out);

}  // namespace rtlab::denoise
