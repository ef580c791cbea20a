#pragma once
// Vocabulary shared by the denoiser stages: luminance, the value range the
// stages keep finite, and the layout conventions of every buffer.
//
// Buffers are plain row-major arrays (index y * width + x, top row first),
// one element per pixel, passed as std::span. Every stage is a free function
// that writes each output pixel from its inputs only, split into fixed 16x16
// tiles (core/parallel.hpp): results are bit-identical for any thread count.
// Outputs never alias inputs unless a function says so.
#include <rtlab/core/math.hpp>

#include <cstddef>

namespace rtlab::denoise {

// Rec. 709 / sRGB-primaries luminance (as in the SVGF paper and Falcor).
inline float luminance(const vec3& c) { return 0.2126f * c.r + 0.7152f * c.g + 0.0722f * c.b; }

// Radiance magnitudes are clamped to this on entry to a stage, and NaN becomes
// 0, so that weighted sums over a 7x7 window stay finite for any finite input.
// A value this large is a bug upstream; the clamp only keeps the output finite.
inline constexpr float kMaxRadiance = 1e30f;
// The luminance used for the second moment is clamped to this, so that
// luminance^2 (and its weighted sums) fit in a float: 1e18^2 = 1e36 < 3.4e38.
inline constexpr float kMaxMomentLuminance = 1e18f;

inline float sanitize(float v) {
    if (!(v == v)) return 0.f;  // NaN
    return v < -kMaxRadiance ? -kMaxRadiance : (v > kMaxRadiance ? kMaxRadiance : v);
}
inline vec3 sanitize(const vec3& c) { return vec3(sanitize(c.r), sanitize(c.g), sanitize(c.b)); }

// First and second luminance moments of one sample (luminance clamped to
// +-kMaxMomentLuminance).
inline vec2 luminanceMoments(const vec3& c) {
    float l = luminance(sanitize(c));
    l = l < -kMaxMomentLuminance ? -kMaxMomentLuminance : (l > kMaxMomentLuminance ? kMaxMomentLuminance : l);
    return vec2(l, l * l);
}

}  // namespace rtlab::denoise
