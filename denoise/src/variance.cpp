#include <rtlab/denoise/variance.hpp>

#include "detail.hpp"
#include "simd.hpp"

namespace rtlab::denoise {

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
    // SoA copies of the depth gradient.
    std::vector<float> gx(n + simd::kWidth, 0.f), gy(n + simd::kWidth, 0.f);
    detail::forEachIndex(n, [&](std::size_t i) { gx[i] = sanitize(grad[i].x), gy[i] = sanitize(grad[i].y); });

    // Step: the temporal estimate, and which pixels need the spatial one.
    const auto needsSpatial = [&](std::size_t i) {
        return !g.isSky(i) && acc.length[i] < params.historyThreshold && radius > 0;
    };
    constexpr int kLanes = simd::kWidth;
    std::vector<float> pixelVariance(n + kLanes, 0.f), mean(n + kLanes, 0.f);
    std::vector<float> depth(n + kLanes, 0.f), nx(n + kLanes, 0.f), ny(n + kLanes, 0.f), nz(n + kLanes, 0.f);
    std::vector<float> geometry(n + kLanes, 0.f);
    detail::forEachIndex(n, [&](std::size_t i) {
        // In float, as the moments were formed: one sample (m2 = fl(m1 * m1)) gives exactly 0.
        const vec2 m = acc.moments[i];
        const float v = m.y - m.x * m.x;
        pixelVariance[i] = v > 0.f ? (v < 1e36f ? v : 1e36f) : 0.f;
        mean[i] = detail::clampNaNLow(m.x, -kMaxMomentLuminance, kMaxMomentLuminance);
        variance[i] = v > 0.f ? v : 0.f;
        if (g.isSky(i)) return;
        geometry[i] = 1.f;
        depth[i] = detail::clampNaNLow(g.depth[i], -kMaxRadiance, kMaxRadiance);
        nx[i] = sanitize(g.normal[i].x), ny[i] = sanitize(g.normal[i].y), nz[i] = sanitize(g.normal[i].z);
    });
    if (radius == 0) return;

    // Step: the spatial estimate, row by row, 4 pixels per vector. The
    // weighted moments are accumulated shifted by the centre's mean:
    //   E[m2] - E[m1]^2 = E[v + (m1 - c)^2] - E[m1 - c]^2   (v = m2 - m1^2 per pixel)
    // which is the same in exact arithmetic and has no cancellation between
    // two large terms in float.
    const simd::NormalPower normalPower(params.sigmaN);
    parallelForEach(static_cast<std::size_t>(h), [&](std::size_t rowIndex) {
        const int y = static_cast<int>(rowIndex);
        const std::size_t row = rowIndex * static_cast<std::size_t>(w);
        std::vector<int> activeBefore(static_cast<std::size_t>(w) + 1, 0);
        for (int x = 0; x < w; ++x) activeBefore[x + 1] = activeBefore[x] + (needsSpatial(row + x) ? 1 : 0);
        if (activeBefore[w] == 0) return;
        const std::size_t padded = static_cast<std::size_t>(w) + kLanes;
        std::vector<float> s0(padded, 1.f), s1(padded, 0.f), s2(padded, 0.f);  // centre: weight 1, deviation 0
        for (int x = 0; x < w; ++x) s2[x] = pixelVariance[row + x];
        const float *pv = pixelVariance.data(), *mu = mean.data(), *z = depth.data(), *geo = geometry.data();
        const float *nxp = nx.data(), *nyp = ny.data(), *nzp = nz.data();
        float *a0 = s0.data(), *a1 = s1.data(), *a2 = s2.data();
        for (int dy = -radius; dy <= radius; ++dy) {
            const int py = y + dy;
            if (py < 0 || py >= h) continue;
            const std::size_t rowQ = static_cast<std::size_t>(py) * static_cast<std::size_t>(w);
            for (int dx = -radius; dx <= radius; ++dx) {
                if (dx == 0 && dy == 0) continue;
                const int x0 = std::max(0, -dx), x1 = std::min(w, w - dx);
                const simd::vf offX = simd::splat(static_cast<float>(dx)), offY = simd::splat(static_cast<float>(dy));
                for (int x = x0; x < x1; x += kLanes) {
                    if (activeBefore[std::min(x + kLanes, w)] == activeBefore[x]) continue;
                    const simd::vf laneMask = x + kLanes <= x1 ? simd::splat(1.f) : simd::tailMask(x1 - x);
                    const std::size_t i = row + x, j = rowQ + x + dx;
                    const simd::vf zc = simd::loadu(z + i);
                    const simd::vf dz = simd::abs(zc - simd::loadu(z + j));
                    const simd::vf zDen =
                        simd::abs(simd::loadu(gx.data() + i) * offX + simd::loadu(gy.data() + i) * offY) * params.sigmaZ +
                        simd::abs(zc) * params.depthEpsilon;
                    const simd::vf termZ = simd::select(dz == 0.f, simd::splat(0.f),
                                                        simd::select(zDen > 0.f, dz / zDen, simd::splat(kInfinity)));
                    const simd::vf d = simd::loadu(nxp + i) * simd::loadu(nxp + j) +
                                       simd::loadu(nyp + i) * simd::loadu(nyp + j) +
                                       simd::loadu(nzp + i) * simd::loadu(nzp + j);
                    const simd::vf wgt = simd::expNeg(termZ) * normalPower(d) * simd::loadu(geo + j) * laneMask;
                    const simd::vf dev = simd::loadu(mu + j) - simd::loadu(mu + i);
                    simd::storeu(a0 + x, simd::loadu(a0 + x) + wgt);
                    simd::storeu(a1 + x, simd::loadu(a1 + x) + wgt * dev);
                    simd::storeu(a2 + x, simd::loadu(a2 + x) + wgt * (simd::loadu(pv + j) + dev * dev));
                }
            }
        }
        for (int x = 0; x < w; ++x) {
            const std::size_t i = row + x;
            if (!needsSpatial(i)) continue;
            const double m1 = static_cast<double>(s1[x]) / s0[x];
            double v = static_cast<double>(s2[x]) / s0[x] - m1 * m1;
            v = v > 0.0 ? v : 0.0;
            if (params.boostShortHistory && acc.length[i] > 0.f)
                v *= static_cast<double>(params.historyThreshold) / acc.length[i];
            variance[i] = v < 3.0e38 ? static_cast<float>(v) : 3.0e38f;
        }
    });
}

}  // namespace rtlab::denoise
