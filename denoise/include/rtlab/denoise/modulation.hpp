#pragma once
// Albedo (or BRDF) demodulation before filtering and remodulation after it, so
// that the filter blurs illumination and not texture detail (SVGF, Schied et
// al. 2017, section 4).
#include <rtlab/denoise/common.hpp>

#include <span>

namespace rtlab::denoise {

// The albedo floor of demodulation. Source: Falcor's SVGFReproject (0.001).
inline constexpr float kDefaultAlbedoEpsilon = 1e-3f;

// out = color / max(albedo, epsilon) per channel (negative albedo counts as 0).
// The result is finite for any finite input (clamped to +-kMaxRadiance).
// `out` may alias `color`.
void demodulate(std::span<const vec3> color, std::span<const vec3> albedo, std::span<vec3> out,
                float epsilon = kDefaultAlbedoEpsilon);

// out = illumination * max(albedo, epsilon): the exact inverse of demodulate
// up to rounding (Falcor multiplies by the raw albedo; the two differ only
// where albedo < epsilon). Finite for any finite input. `out` may alias
// `illumination`.
void remodulate(std::span<const vec3> illumination, std::span<const vec3> albedo, std::span<vec3> out,
                float epsilon = kDefaultAlbedoEpsilon);

}  // namespace rtlab::denoise
