#include <rtlab/denoise/variance.hpp>

#include "detail.hpp"
#include "simd.hpp"

namespace rtlab::denoise {

namespace {

// One row's off-centre taps of the spatial estimate, accumulated into its
// weight sum, weighted mean deviation and weighted second moment.
struct MomentRow {
    const float *pixelVariance, *mean, *depth, *geometry, *nx, *ny, *nz, *gradX, *gradY;
    float *s0, *s1, *s2;
    const int* activeBefore;  // prefix count of the pixels that need the spatial estimate
    int w, h, y, radius;
    std::size_t row;
    float sigmaZ, depthEps;
    const simd::NormalPower* normalPower;
};

template <int N>
RTLAB_SIMD_INLINE void accumulateMoments(const MomentRow& t) {
    using V = simd::vfloat<N>;
    const int w = t.w;
    for (int dy = -t.radius; dy <= t.radius; ++dy) {
        const int py = t.y + dy;
        if (py < 0 || py >= t.h) continue;
        const std::size_t rowQ = static_cast<std::size_t>(py) * static_cast<std::size_t>(w);
        for (int dx = -t.radius; dx <= t.radius; ++dx) {
            if (dx == 0 && dy == 0) continue;
            const int x0 = std::max(0, -dx), x1 = std::min(w, w - dx);
            const V offX = simd::splat<N>(static_cast<float>(dx)), offY = simd::splat<N>(static_cast<float>(dy));
            for (int x = x0; x < x1; x += N) {
                if (t.activeBefore[std::min(x + N, w)] == t.activeBefore[x]) continue;
                const V laneMask = x + N <= x1 ? simd::splat<N>(1.f) : simd::tailMask<N>(x1 - x);
                const std::size_t i = t.row + x, j = rowQ + x + dx;
                const V termZ = simd::depthTerm<N>(simd::loadu<N>(t.depth + i), simd::loadu<N>(t.depth + j),
                                                   simd::loadu<N>(t.gradX + i), simd::loadu<N>(t.gradY + i), offX,
                                                   offY, t.sigmaZ, t.depthEps);
                const V wgt = simd::expNeg<N>(termZ) * t.normalPower->apply<N>(simd::normalDot<N>(t.nx, t.ny, t.nz, i, j)) *
                              simd::loadu<N>(t.geometry + j) * laneMask;
                const V dev = simd::loadu<N>(t.mean + j) - simd::loadu<N>(t.mean + i);
                simd::storeu<N>(t.s0 + x, simd::loadu<N>(t.s0 + x) + wgt);
                simd::storeu<N>(t.s1 + x, simd::loadu<N>(t.s1 + x) + wgt * dev);
                simd::storeu<N>(t.s2 + x,
                                simd::loadu<N>(t.s2 + x) + wgt * (simd::loadu<N>(t.pixelVariance + j) + dev * dev));
            }
        }
    }
}

// The same, compiled for AVX2 (picked at run time by simd::preferredWidth).
__attribute__((target("avx2"))) void accumulateMomentsAvx2(const MomentRow& t) { accumulateMoments<8>(t); }

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
    // SoA copies of the depth gradient.
    std::vector<float> gx(n + simd::kMaxWidth, 0.f), gy(n + simd::kMaxWidth, 0.f);
    detail::forEachIndex(n, [&](std::size_t i) { gx[i] = sanitize(grad[i].x), gy[i] = sanitize(grad[i].y); });

    // Step: the temporal estimate, and which pixels need the spatial one.
    const auto needsSpatial = [&](std::size_t i) {
        return !g.isSky(i) && acc.length[i] < params.historyThreshold && radius > 0;
    };
    constexpr int kLanes = simd::kMaxWidth;  // padding
    std::vector<float> pixelVariance(n + kLanes, 0.f), mean(n + kLanes, 0.f);
    std::vector<float> depth(n + kLanes, 0.f), nx(n + kLanes, 0.f), ny(n + kLanes, 0.f), nz(n + kLanes, 0.f);
    std::vector<float> geometry(n + kLanes, 0.f);
    detail::forEachIndex(n, [&](std::size_t i) {
        // In float, as the moments were formed: one sample (m2 = fl(m1 * m1)) gives exactly 0.
        const vec2 m = acc.moments[i];
        const float v = m.y - m.x * m.x;
        pixelVariance[i] = v > 0.f ? (v < 1e36f ? v : 1e36f) : 0.f;
        mean[i] = detail::clampNaNLow(m.x, -kMaxMomentLuminance, kMaxMomentLuminance);
        variance[i] = v > 0.f ? (v < 3.0e38f ? v : 3.0e38f) : 0.f;  // +Inf moments stay finite
        if (g.isSky(i)) return;
        geometry[i] = 1.f;
        depth[i] = detail::clampNaNLow(g.depth[i], -kMaxRadiance, kMaxRadiance);
        nx[i] = sanitize(g.normal[i].x), ny[i] = sanitize(g.normal[i].y), nz[i] = sanitize(g.normal[i].z);
    });
    if (radius == 0) return;

    // Step: the spatial estimate, row by row, 4 or 8 pixels per vector. The
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
        const MomentRow t{pixelVariance.data(), mean.data(), depth.data(), geometry.data(), nx.data(), ny.data(),
                          nz.data(), gx.data(), gy.data(), s0.data(), s1.data(), s2.data(), activeBefore.data(),
                          w, h, y, radius, row, params.sigmaZ, params.depthEpsilon, &normalPower};
        if (simd::preferredWidth() == 8) accumulateMomentsAvx2(t);
        else accumulateMoments<4>(t);
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
