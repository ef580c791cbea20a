#pragma once
// Neighbourhood clamps: firefly (outlier) removal on the noisy input, and
// clamping of the reprojected history to the current frame's neighbourhood
// (the TAA-style guard against ghosting; not part of the SVGF paper).
#include <rtlab/denoise/common.hpp>

#include <span>

namespace rtlab::denoise {

struct FireflyClampParams {
    // Window half-width: 1 = 3x3, 2 = 5x5. Source: rtlab.
    int radius = 1;
    // Each channel is clamped to mean +- k * sigma of its neighbours (the centre
    // excluded, so a single firefly cannot widen its own bounds). Source: rtlab.
    float k = 3.f;
};

// out[i] = clamp(in[i], mean - k sigma, mean + k sigma) per channel, mean and
// sigma over the window's other on-screen pixels (none: unchanged). A pixel
// inside its bounds is copied bit-exactly. `out` must not alias `in`.
void clampFireflies(int width, int height, std::span<const vec3> in, std::span<vec3> out,
                    const FireflyClampParams& params = {});

enum class HistoryClampMode {
    None,       // history used as is (paper)
    MinMax,     // clamp to the per-channel min/max of the current window
    MeanSigma,  // clamp to mean +- k sigma of the current window (variance clipping)
};

struct HistoryClampParams {
    HistoryClampMode mode = HistoryClampMode::None;  // Source: paper (no clamp).
    int radius = 1;                                  // 3x3. Source: rtlab.
    // For MeanSigma. Source: the usual TAA variance-clipping gamma (~1).
    float k = 1.f;
};

// Clamps history[i] (in place) to the bounds of `current` around pixel i, with
// the centre included. Pixels with historyLength[i] == 0 (no history) are left
// alone; an empty historyLength clamps every pixel.
void clampHistory(int width, int height, std::span<const vec3> current, std::span<vec3> history,
                  std::span<const float> historyLength, const HistoryClampParams& params);

}  // namespace rtlab::denoise
