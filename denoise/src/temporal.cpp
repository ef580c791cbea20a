#include <rtlab/denoise/temporal.hpp>

#include "detail.hpp"

namespace rtlab::denoise {

void HistoryBuffers::resize(int w, int h) {
    const std::size_t n = detail::pixelCount(w, h);
    width = w;
    height = h;
    color.assign(n, vec3(0.f));
    moments.assign(n, vec2(0.f));
    length.assign(n, 0.f);
}

namespace {
// x + a (y - x): exactly x when y == x (glm::mix's x(1-a) + ya is not).
template <class T>
T blend(const T& x, const T& y, float a) {
    return x + a * (y - x);
}

void checkHistory(const HistoryBuffers& h, const char* what) {
    const std::size_t n = detail::pixelCount(h.width, h.height);
    detail::checkSize(h.color.size(), n, what);
    detail::checkSize(h.moments.size(), n, what);
    detail::checkSize(h.length.size(), n, what);
}
}  // namespace

void reprojectHistory(const Reprojection& r, const HistoryBuffers& previous, HistoryBuffers& out) {
    checkHistory(previous, "reprojectHistory: previous");
    if (previous.width != r.width || previous.height != r.height)
        throw std::invalid_argument("denoise::reprojectHistory: history and reprojection differ in size");
    out.resize(r.width, r.height);
    gather(r, std::span<const vec3>(previous.color), std::span<vec3>(out.color));
    gather(r, std::span<const vec2>(previous.moments), std::span<vec2>(out.moments));
    gather(r, std::span<const float>(previous.length), std::span<float>(out.length));
}

void accumulateTemporal(std::span<const vec3> color, const HistoryBuffers& reprojected, const TemporalParams& params,
                        HistoryBuffers& out) {
    checkHistory(reprojected, "accumulateTemporal: reprojected");
    const int w = reprojected.width, h = reprojected.height;
    const std::size_t n = reprojected.pixelCount();
    detail::checkSize(color.size(), n, "accumulateTemporal: color");
    if (&out != &reprojected) {
        out.width = w;
        out.height = h;
        out.color.resize(n);
        out.moments.resize(n);
        out.length.resize(n);
    }
    const float maxLen = params.maxHistoryLength >= 1.f ? params.maxHistoryLength : 1.f;
    detail::forEachPixel(w, h, [&](int, int, std::size_t i) {
        const vec3 sample = sanitize(color[i]);
        const vec2 m = luminanceMoments(sample);
        const float prevLen = reprojected.length[i];
        if (prevLen > 0.f) {
            const float len = prevLen + 1.f < maxLen ? prevLen + 1.f : maxLen;
            const float a = params.alpha > 1.f / len ? params.alpha : 1.f / len;
            const float am = params.momentsAlpha > 1.f / len ? params.momentsAlpha : 1.f / len;
            out.color[i] = blend(reprojected.color[i], sample, a);
            out.moments[i] = blend(reprojected.moments[i], m, am);
            out.length[i] = len;
        } else {
            out.color[i] = sample;
            out.moments[i] = m;
            out.length[i] = 1.f;
        }
    });
}

}  // namespace rtlab::denoise
