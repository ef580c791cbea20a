#include <rtlab/denoise/clamp.hpp>

#include "detail.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

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

// Per-pixel sums of v and v^2 (per channel, double) over the (2r+1)^2
// window clipped to the image, and the window's pixel count: a separable
// box (row sums, then column sums of those), O(r) per pixel instead of O(r^2).
struct BoxMoments {
    std::vector<glm::dvec3> sum, sum2;
    std::vector<int> count;
};

BoxMoments boxMoments(int width, int height, std::span<const vec3> img, int radius) {
    const std::size_t n = img.size();
    std::vector<glm::dvec3> rowSum(n), rowSum2(n);
    detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
        const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(width);
        glm::dvec3 a(0.0), b(0.0);
        for (int px = std::max(0, x - radius); px <= std::min(width - 1, x + radius); ++px) {
            const glm::dvec3 v(sanitize(img[row + px]));
            a += v;
            b += v * v;
        }
        rowSum[i] = a;
        rowSum2[i] = b;
    });
    BoxMoments m{std::vector<glm::dvec3>(n), std::vector<glm::dvec3>(n), std::vector<int>(n)};
    detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
        glm::dvec3 a(0.0), b(0.0);
        const int y0 = std::max(0, y - radius), y1 = std::min(height - 1, y + radius);
        for (int py = y0; py <= y1; ++py) {
            const std::size_t j = static_cast<std::size_t>(py) * static_cast<std::size_t>(width) + x;
            a += rowSum[j];
            b += rowSum2[j];
        }
        m.sum[i] = a;
        m.sum2[i] = b;
        m.count[i] = (std::min(width - 1, x + radius) - std::max(0, x - radius) + 1) * (y1 - y0 + 1);
    });
    return m;
}

// Mean and standard deviation from window sums (count > 0).
void meanSigma(const glm::dvec3& sum, const glm::dvec3& sum2, int count, double mean[3], double sigma[3]) {
    for (int c = 0; c < 3; ++c) {
        mean[c] = sum[c] / count;
        const double var = sum2[c] / count - mean[c] * mean[c];
        sigma[c] = var > 0.0 ? std::sqrt(var) : 0.0;
    }
}

}  // namespace

void clampFireflies(int width, int height, std::span<const vec3> in, std::span<vec3> out,
                    const FireflyClampParams& params) {
    const std::size_t n = detail::pixelCount(width, height);
    detail::checkSize(in.size(), n, "clampFireflies: in");
    detail::checkSize(out.size(), n, "clampFireflies: out");
    const int radius = std::clamp(params.radius, 1, 16);
    const double k = params.k > 0.f ? params.k : 0.0;
    // Direct window sums (the centre excluded): subtracting a 1e30 firefly
    // from box sums would cancel its neighbours away.
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
    // No pixel with a history (a first frame): nothing to clamp, no window statistics.
    if (!historyLength.empty() &&
        std::none_of(historyLength.begin(), historyLength.end(), [](float l) { return l > 0.f; }))
        return;
    const int radius = std::clamp(params.radius, 0, 16);
    const double k = params.k > 0.f ? params.k : 0.0;
    if (params.mode == HistoryClampMode::MinMax) {
        detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
            if (!historyLength.empty() && !(historyLength[i] > 0.f)) return;
            const vec3 hc = sanitize(history[i]);
            const WindowStats s = windowStats(width, height, current, x, y, radius, true);
            vec3 r;
            for (int ch = 0; ch < 3; ++ch) r[ch] = clampTo(hc[ch], s.lo[ch], s.hi[ch]);
            history[i] = r;
        });
        return;
    }
    // Mean +- k sigma: from separable box sums.
    const BoxMoments box = boxMoments(width, height, current, radius);
    detail::forEachPixel(width, height, [&](int, int, std::size_t i) {
        if (!historyLength.empty() && !(historyLength[i] > 0.f)) return;
        const vec3 hc = sanitize(history[i]);
        double mean[3], sigma[3];
        meanSigma(box.sum[i], box.sum2[i], box.count[i], mean, sigma);
        vec3 r;
        for (int ch = 0; ch < 3; ++ch) r[ch] = clampTo(hc[ch], mean[ch] - k * sigma[ch], mean[ch] + k * sigma[ch]);
        history[i] = r;
    });
}

}  // namespace rtlab::denoise
