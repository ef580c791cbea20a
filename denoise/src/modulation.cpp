#include <rtlab/denoise/modulation.hpp>

#include "detail.hpp"

#include <stdexcept>
#include <string>

namespace rtlab::denoise {

namespace {

float floorAlbedo(float a, float eps) {
    // NaN and anything below eps -> eps; above kMaxRadiance -> kMaxRadiance.
    if (!(a > eps)) return eps;
    return a < kMaxRadiance ? a : kMaxRadiance;
}

template <class Op>
void perPixel(std::span<const vec3> a, std::span<const vec3> b, std::span<vec3> out, float eps, const char* what,
              Op op) {
    detail::checkSize(b.size(), a.size(), what);
    detail::checkSize(out.size(), a.size(), what);
    if (!(eps > 0.f)) throw std::invalid_argument(std::string("denoise: ") + what + ": epsilon must be > 0");
    detail::forEachIndex(a.size(), [&](std::size_t i) {
        const vec3 c = sanitize(a[i]);
        const vec3 al = b[i];
        vec3 r;
        for (int ch = 0; ch < 3; ++ch) r[ch] = sanitize(op(c[ch], floorAlbedo(al[ch], eps)));
        out[i] = r;
    });
}

}  // namespace

void demodulate(std::span<const vec3> color, std::span<const vec3> albedo, std::span<vec3> out, float epsilon) {
    perPixel(color, albedo, out, epsilon, "demodulate", [](float c, float a) { return c / a; });
}

void remodulate(std::span<const vec3> illumination, std::span<const vec3> albedo, std::span<vec3> out, float epsilon) {
    perPixel(illumination, albedo, out, epsilon, "remodulate", [](float c, float a) { return c * a; });
}

}  // namespace rtlab::denoise
