#include <rtlab/denoise/clamp.hpp>

#include "detail.hpp"

#include <algorithm>
#include <cmath>

namespace rtlab::denoise {

namespace {

struct WindowStats {
    double mean[3] = {0, 0, 0};
    double sigma[3] = {0, 0, 0};
    float lo[3] = {0, 0, 0};
    float hi[3] = {0, 0, 0};
    int count = 0;
};

WindowStats windowStats(int width, int height, std::span<const vec3> img, int x, int y, int radius,
                        bool includeCentre) {
    WindowStats s;
    double sum[3] = {0, 0, 0}, sum2[3] = {0, 0, 0};
    for (int c = 0; c < 3; ++c) {
        s.lo[c] = kInfinity;
        s.hi[c] = -kInfinity;
    }
    for (int dy = -radius; dy <= radius; ++dy) {
        const int py = y + dy;
        if (py < 0 || py >= height) continue;
        for (int dx = -radius; dx <= radius; ++dx) {
            const int px = x + dx;
            if (px < 0 || px >= width || (!includeCentre && dx == 0 && dy == 0)) continue;
            const vec3 v = sanitize(img[static_cast<std::size_t>(py) * static_cast<std::size_t>(width) + px]);
            for (int c = 0; c < 3; ++c) {
                sum[c] += v[c];
                sum2[c] += static_cast<double>(v[c]) * v[c];
                s.lo[c] = std::min(s.lo[c], v[c]);
                s.hi[c] = std::max(s.hi[c], v[c]);
            }
            ++s.count;
        }
    }
    if (s.count == 0) return s;
    for (int c = 0; c < 3; ++c) {
        s.mean[c] = sum[c] / s.count;
        const double var = sum2[c] / s.count - s.mean[c] * s.mean[c];
        s.sigma[c] = var > 0.0 ? std::sqrt(var) : 0.0;
    }
    return s;
}

// v clamped to [lo, hi] (doubles); v itself when inside, bit-exactly.
float clampTo(float v, double lo, double hi) {
    if (static_cast<double>(v) < lo) return static_cast<float>(lo);
    if (static_cast<double>(v) > hi) return static_cast<float>(hi);
    return v;
}

}  // namespace

void clampFireflies(int width, int height, std::span<const vec3> in, std::span<vec3> out,
                    const FireflyClampParams& params) {
    const std::size_t n = detail::pixelCount(width, height);
    detail::checkSize(in.size(), n, "clampFireflies: in");
    detail::checkSize(out.size(), n, "clampFireflies: out");
    const int radius = std::clamp(params.radius, 1, 16);
    const double k = params.k > 0.f ? params.k : 0.0;
    detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
        const vec3 c = sanitize(in[i]);
        const WindowStats s = windowStats(width, height, in, x, y, radius, false);
        if (s.count == 0) {
            out[i] = c;
            return;
        }
        vec3 r;
        for (int ch = 0; ch < 3; ++ch)
            r[ch] = clampTo(c[ch], s.mean[ch] - k * s.sigma[ch], s.mean[ch] + k * s.sigma[ch]);
        out[i] = r;
    });
}

void clampHistory(int width, int height, std::span<const vec3> current, std::span<vec3> history,
                  std::span<const float> historyLength, const HistoryClampParams& params) {
    const std::size_t n = detail::pixelCount(width, height);
    detail::checkSize(current.size(), n, "clampHistory: current");
    detail::checkSize(history.size(), n, "clampHistory: history");
    if (!historyLength.empty()) detail::checkSize(historyLength.size(), n, "clampHistory: historyLength");
    if (params.mode == HistoryClampMode::None) return;
    const int radius = std::clamp(params.radius, 0, 16);
    const double k = params.k > 0.f ? params.k : 0.0;
    detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
        if (!historyLength.empty() && !(historyLength[i] > 0.f)) return;
        const vec3 hc = sanitize(history[i]);
        const WindowStats s = windowStats(width, height, current, x, y, radius, true);
        vec3 r;
        for (int ch = 0; ch < 3; ++ch) {
            if (params.mode == HistoryClampMode::MinMax)
                r[ch] = clampTo(hc[ch], s.lo[ch], s.hi[ch]);
            else
                r[ch] = clampTo(hc[ch], s.mean[ch] - k * s.sigma[ch], s.mean[ch] + k * s.sigma[ch]);
        }
        history[i] = r;
    });
}

}  // namespace rtlab::denoise
