#include <rtlab/denoise/variance.hpp>

#include "detail.hpp"

namespace rtlab::denoise {

namespace {
float varianceOf(double m1, double m2) {
    const double v = m2 - m1 * m1;
    if (!(v > 0.0)) return 0.f;
    return v < 3.0e38 ? static_cast<float>(v) : 3.0e38f;
}
}  // namespace

void estimateVariance(const GuideBuffers& g, const HistoryBuffers& acc, const VarianceParams& params,
                      std::span<float> variance) {
    std::vector<vec2> scratch;
    const std::vector<vec2>& grad = detail::gradientOf(g, scratch);
    const std::size_t n = g.pixelCount();
    if (acc.width != g.width || acc.height != g.height)
        throw std::invalid_argument("denoise::estimateVariance: history and guides differ in size");
    detail::checkSize(acc.moments.size(), n, "estimateVariance: moments");
    detail::checkSize(acc.length.size(), n, "estimateVariance: length");
    detail::checkSize(variance.size(), n, "estimateVariance: variance");
    const int w = g.width, h = g.height;
    const int radius = params.radius > 0 ? params.radius : 0;
    const detail::NormalWeight normalWeight(params.sigmaN);

    detail::forEachPixel(w, h, [&](int x, int y, std::size_t i) {
        const vec2 mc = acc.moments[i];
        if (g.isSky(i) || acc.length[i] >= params.historyThreshold || radius == 0) {
            // In float, as the moments were formed: one sample (m2 = fl(m1 * m1)) gives exactly 0.
            const float v = mc.y - mc.x * mc.x;
            variance[i] = v > 0.f ? v : 0.f;
            return;
        }
        const float z = g.depth[i];
        const vec3 nrm = g.normal[i];
        double sumW = 1.0, sum1 = mc.x, sum2 = mc.y;  // centre, weight 1
        for (int dy = -radius; dy <= radius; ++dy) {
            const int py = y + dy;
            if (py < 0 || py >= h) continue;
            for (int dx = -radius; dx <= radius; ++dx) {
                const int px = x + dx;
                if (px < 0 || px >= w || (dx == 0 && dy == 0)) continue;
                const std::size_t j = static_cast<std::size_t>(py) * static_cast<std::size_t>(w) + px;
                if (g.isSky(j)) continue;
                const float wz = detail::depthTerm(z, g.depth[j], grad[i], vec2(dx, dy), params.sigmaZ,
                                                   params.depthEpsilon);
                const float wgt = detail::expNeg(wz) * normalWeight(nrm, g.normal[j]);
                if (!(wgt > 0.f)) continue;
                sumW += wgt;
                sum1 += static_cast<double>(wgt) * acc.moments[j].x;
                sum2 += static_cast<double>(wgt) * acc.moments[j].y;
            }
        }
        double v = static_cast<double>(varianceOf(sum1 / sumW, sum2 / sumW));
        if (params.boostShortHistory && acc.length[i] > 0.f) v *= static_cast<double>(params.historyThreshold) / acc.length[i];
        variance[i] = v < 3.0e38 ? static_cast<float>(v) : 3.0e38f;
    });
}

}  // namespace rtlab::denoise
