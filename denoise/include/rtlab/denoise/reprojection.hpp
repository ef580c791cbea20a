#pragma once
// Temporal reprojection with consistency checks (SVGF, Schied et al. 2017,
// section 4.1): each pixel finds where it was in the previous frame through
// its motion vector, and takes a bilinear gather over the 2x2 previous pixels
// around that position, dropping the taps that fail a consistency test and
// renormalising the weights of the rest.
#include <rtlab/denoise/guides.hpp>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace rtlab::denoise {

struct ReprojectionParams {
    // A tap is rejected when |z - z_prev| > depthThreshold * (fwidth(z) + depthEpsilon),
    // fwidth(z) = |dz/dx| + |dz/dy| of the current pixel. Source: Falcor's
    // SVGFReproject (threshold 10, epsilon 1e-2 in depth units); the paper
    // names the depth test but gives no numbers.
    float depthThreshold = 10.f;
    float depthEpsilon = 1e-2f;
    // A tap is rejected when dot(n, n_prev) < normalThreshold (cos ~25.8 deg).
    // Source: rtlab. Falcor instead rejects |n - n_prev| / (fwidth(n) + 1e-2) > 16,
    // i.e. dot < 0.987 on a flat surface; the paper gives no number.
    float normalThreshold = 0.9f;
    // The surviving bilinear weight must be at least this for the history to
    // count (Falcor: 0.01).
    float minWeight = 0.01f;
};

// Where one pixel's history comes from: up to four previous pixels with
// renormalised weights (summing to 1 when the pixel is valid; all 0 when not).
struct ReprojectionTaps {
    std::uint32_t index[4] = {0, 0, 0, 0};  // row-major indices into the previous frame
    float weight[4] = {0.f, 0.f, 0.f, 0.f};
};

struct Reprojection {
    int width = 0;
    int height = 0;
    std::vector<ReprojectionTaps> taps;
    std::vector<std::uint8_t> valid;  // 1 = history found, 0 = disoccluded / off-screen
    std::size_t validCount() const;
};

// Reprojects every pixel of `current` into `previous` (same size, else
// std::invalid_argument). Previous position = pixel centre + motion. The pixel
// is invalid when that position is off screen; otherwise each of the 2x2
// bilinear taps passes when it is on screen, has non-zero bilinear weight, the
// same mesh id, and (on geometry) passes the depth and normal tests. Sky
// pixels (mesh id -1) match sky taps on mesh id alone.
Reprojection reproject(const GuideBuffers& current, const GuideBuffers& previous,
                       const ReprojectionParams& params = {});

// out[i] = sum_k weight_k * previous[index_k] for valid pixels, `invalidValue`
// for the others. `out` must not alias `previous`; sizes must match.
void gather(const Reprojection& r, std::span<const float> previous, std::span<float> out, float invalidValue = 0.f);
void gather(const Reprojection& r, std::span<const vec2> previous, std::span<vec2> out, vec2 invalidValue = vec2(0.f));
void gather(const Reprojection& r, std::span<const vec3> previous, std::span<vec3> out, vec3 invalidValue = vec3(0.f));

}  // namespace rtlab::denoise
