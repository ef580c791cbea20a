#include <rtlab/denoise/variance.hpp>

#include "detail.hpp"
#include "simd.hpp"

namespace rtlab::denoise {

namespace {

// The largest window the register-held reciprocals cover (radius 3: 7x7).
constexpr int kMaxFastRadius = 3;
constexpr int kMaxHalfTaps = ((2 * kMaxFastRadius + 1) * (2 * kMaxFastRadius + 1) - 1) / 2;

// One row's off-centre taps of the spatial estimate, accumulated into its
// weight sum, weighted mean deviation and weighted second moment.
struct MomentRow {
    const float *pixelVariance, *mean, *depth, *geometry, *nx, *ny, *nz, *gradX, *gradY;
    float *s0, *s1, *s2;
    const int* activeBefore;  // prefix count of the pixels that need the spatial estimate
    int w, h, y, radius;      // radius <= kMaxFastRadius
    std::size_t row;
    float sigmaZ, depthEps;
    const simd::NormalPower* normalPower;
};

// Per vector of N pixels, every tap in (dy, dx) order with the sums held in
// registers. The depth term's reciprocal denominators are computed once per
// pixel for each offset and its negative (they share |grad . offset|).
// (Weights read from a float's bits, as the a-trous passes do, were 1 ms
// faster at 480x270 but raised the SVGF stack's one-frame GI error on
// showcase by 2.5 %: their exp is within +6.2 %.)
// A tap whose neighbour lies outside the row (x + dx outside [0, w)) or a
// lane past the row's end reads finite padding or the next row and adds
// exactly 0: its weight is masked. The planes are padded by kMaxWidth +
// radius floats before the first and after the last pixel.
template <int N>
RTLAB_SIMD_INLINE void accumulateMoments(const MomentRow& t) {
    using V = simd::vfloat<N>;
    using VI = simd::vint<N>;
    const int w = t.w, r = t.radius;
    VI laneIndex;
    for (int lane = 0; lane < N; ++lane) laneIndex[lane] = lane;
    const V one = simd::splat<N>(1.f), zero = simd::opaque<N>(simd::splat<N>(0.f));
    const V minDen = simd::opaque<N>(simd::splat<N>(1e-30f));
    for (int x = 0; x < w; x += N) {
        if (t.activeBefore[std::min(x + N, w)] == t.activeBefore[x]) continue;
        const std::size_t i = t.row + static_cast<std::size_t>(x);
        const V z = simd::loadu<N>(t.depth + i), mean = simd::loadu<N>(t.mean + i);
        const V cx = simd::loadu<N>(t.nx + i), cy = simd::loadu<N>(t.ny + i), cz = simd::loadu<N>(t.nz + i);
        // Step: 1 / (sigmaZ |grad . offset| + eps |z|) for the offsets with dy > 0
        // or dy = 0 < dx (the others are their negatives), in (dy, dx) order.
        const V gA = simd::loadu<N>(t.gradX + i) * t.sigmaZ, gB = simd::loadu<N>(t.gradY + i) * t.sigmaZ;
        const V eps = simd::abs<N>(z) * t.depthEps;
        V rZ[kMaxHalfTaps];
        int k = 0;
        for (int dy = 0; dy <= r; ++dy)
            for (int dx = dy == 0 ? 1 : -r; dx <= r; ++dx, ++k) {
                const V den = simd::abs<N>(gA * static_cast<float>(dx) + gB * static_cast<float>(dy)) + eps;
                rZ[k] = simd::splat<N>(1.f) / simd::max<N>(den, minDen);
            }
        const VI px = laneIndex + x;
        const VI inRow = px < w;
        // Step: the centre (weight 1, deviation 0, its own variance), then the taps.
        V s0 = one, s1 = zero, s2 = simd::loadu<N>(t.pixelVariance + i);
        for (int dy = -r; dy <= r; ++dy) {
            const int py = t.y + dy;
            if (py < 0 || py >= t.h) continue;
            const std::size_t rowQ = static_cast<std::size_t>(py) * static_cast<std::size_t>(w);
            for (int dx = -r; dx <= r; ++dx) {
                if (dx == 0 && dy == 0) continue;
                // The offset's index among the half taps (its negative shares it).
                const bool upper = dy > 0 || (dy == 0 && dx > 0);
                const int ax = upper ? dx : -dx, ay = upper ? dy : -dy;
                const int kOffset = ay == 0 ? ax - 1 : r + (ay - 1) * (2 * r + 1) + (ax + r);
                const VI qx = px + dx;
                const V laneMask = simd::select<N>(inRow & (qx >= 0) & (qx < w), one, zero);
                // j may lie up to radius before the row's first pixel: the planes' front padding.
                const std::ptrdiff_t j = static_cast<std::ptrdiff_t>(rowQ) + x + dx;
                const V dot =
                    cx * simd::loadu<N>(t.nx + j) + cy * simd::loadu<N>(t.ny + j) + cz * simd::loadu<N>(t.nz + j);
                const V eZ = simd::abs<N>(z - simd::loadu<N>(t.depth + j)) * rZ[kOffset];
                const V wgt = simd::expNegWeight<N>(eZ) * t.normalPower->apply<N>(dot) *
                              simd::loadu<N>(t.geometry + j) * laneMask;
                const V dev = simd::loadu<N>(t.mean + j) - mean;
                s0 = s0 + wgt;
                s1 = s1 + wgt * dev;
                s2 = s2 + wgt * (simd::loadu<N>(t.pixelVariance + j) + dev * dev);
            }
        }
        simd::storeu<N>(t.s0 + x, s0);
        simd::storeu<N>(t.s1 + x, s1);
        simd::storeu<N>(t.s2 + x, s2);
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
    const int radius = std::clamp(params.radius, 0, kMaxFastRadius);
    // SoA copies of the depth gradient.
    std::vector<float> gx(n + simd::kMaxWidth, 0.f), gy(n + simd::kMaxWidth, 0.f);  // read at the centre only
    detail::forEachIndex(n, [&](std::size_t i) { gx[i] = sanitize(grad[i].x), gy[i] = sanitize(grad[i].y); });

    // Step: the temporal estimate, and which pixels need the spatial one.
    const auto needsSpatial = [&](std::size_t i) {
        return !g.isSky(i) && acc.length[i] < params.historyThreshold && radius > 0;
    };
    // Planes padded before the first and after the last pixel (zeros: finite,
    // weight 0), so that a tap's vector load never leaves them.
    const std::size_t pad = static_cast<std::size_t>(simd::kMaxWidth + radius);
    std::vector<float> planes(7 * (n + 2 * pad), 0.f);
    const auto plane = [&](int k) { return planes.data() + static_cast<std::size_t>(k) * (n + 2 * pad) + pad; };
    float *pixelVariance = plane(0), *mean = plane(1), *depth = plane(2), *nx = plane(3), *ny = plane(4),
          *nz = plane(5), *geometry = plane(6);
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
        const vec3 normal = detail::guideUnitNormal(g.normal[i]);
        nx[i] = normal.x, ny[i] = normal.y, nz[i] = normal.z;
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
        const std::size_t padded = static_cast<std::size_t>(w) + simd::kMaxWidth;
        std::vector<float> s0(padded), s1(padded), s2(padded);
        const MomentRow t{pixelVariance,
                          mean,
                          depth,
                          geometry,
                          nx,
                          ny,
                          nz,
                          gx.data(),
                          gy.data(),
                          s0.data(),
                          s1.data(),
                          s2.data(),
                          activeBefore.data(),
                          w,
                          h,
                          y,
                          radius,
                          row,
                          params.sigmaZ > 0.f ? params.sigmaZ : 0.f,
                          params.depthEpsilon > 0.f ? params.depthEpsilon : 0.f,
                          &normalPower};
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
