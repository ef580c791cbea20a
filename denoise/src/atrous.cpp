#include <rtlab/denoise/atrous.hpp>

#include "detail.hpp"
#include "simd.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <vector>

namespace rtlab::denoise {

namespace {

constexpr int kLanes = simd::kMaxWidth;  // padding after the planes' last pixel

constexpr float kKernel[3] = {3.f / 8.f, 1.f / 4.f, 1.f / 16.f};
// Input variances are clamped to this so that sum h^2 w^2 Var over 25 taps,
// divided by (sum h w)^2 >= (9/64)^2, stays a finite float.
constexpr float kMaxVariance = 1e36f;

float clampVariance(float v) { return v > 0.f ? (v < kMaxVariance ? v : kMaxVariance) : 0.f; }

void checkInputs(const GuideBuffers& g, std::span<const vec3> color, std::span<const float> variance,
                 std::span<vec3> colorOut, std::span<float> varianceOut) {
    const std::size_t n = g.pixelCount();
    detail::checkSize(color.size(), n, "atrous: color");
    detail::checkSize(variance.size(), n, "atrous: variance");
    detail::checkSize(colorOut.size(), n, "atrous: colorOut");
    detail::checkSize(varianceOut.size(), n, "atrous: varianceOut");
}

// The planes' layout: rows of `stride` floats with `margin` zero floats on
// both sides, and `top` zero rows above the first row and below the last,
// so that a tap up to `fastReach` pixels away in x and y (and, with range
// checks on rows, up to margin - kLanes in x) reads a zero (normal 0 and
// geometry 0: weight 0) instead of another row or memory outside the planes.
// The margins are zeroed when the layout changes and never written after
// (the last vector of a row stores the values it read there: zeros).
struct Layout {
    int width = 0, height = 0, margin = 0, stride = 0, top = 0, fastReach = 0;
    std::size_t size() const {
        return static_cast<std::size_t>(height + 2 * top) * static_cast<std::size_t>(stride) + kLanes;
    }
    std::size_t at(int x, int y) const {
        return static_cast<std::size_t>(y + top) * static_cast<std::size_t>(stride) +
               static_cast<std::size_t>(margin + x);
    }
    bool operator==(const Layout&) const = default;
    // Taps up to 2 * maxStep pixels away. Steps with 2 * step <= fastReach
    // (every step up to 32) run without range checks; larger ones check rows
    // and skip taps with |dx| >= width (no pixel of the row).
    static Layout of(int w, int h, int maxStep) {
        Layout l;
        l.width = w;
        l.height = h;
        const long reach = 2L * maxStep;
        l.fastReach = static_cast<int>(std::min<long>(reach, kMaxFastReach));
        const long horizontal = std::max<long>(std::min<long>(reach, static_cast<long>(w)), l.fastReach);
        l.margin = static_cast<int>((horizontal + kLanes + kLanes - 1) / kLanes * kLanes);
        l.stride = w + 2 * l.margin;
        l.top = std::max(l.fastReach, 1);  // >= 1: the 3x3 variance blur reads rows y +- 1
        return l;
    }
    static constexpr long kMaxFastReach = 64;
};

void fitPlane(std::vector<float>& plane, const Layout& l, bool relayout) {
    if (relayout || plane.size() != l.size()) plane.assign(l.size(), 0.f);
}

// Runs f(x, y, plane index, pixel index) for every pixel, one task per row.
template <class F>
void forEachRow(const Layout& l, F&& f) {
    parallelForEach(static_cast<std::size_t>(l.height), [&](std::size_t rowIndex) {
        const int y = static_cast<int>(rowIndex);
        const std::size_t row = rowIndex * static_cast<std::size_t>(l.width);
        for (int x = 0; x < l.width; ++x) f(x, y, l.at(x, y), row + static_cast<std::size_t>(x));
    });
}

// The guides as structure-of-arrays floats (padded rows), built once per filter call.
struct GuidePlanes {
    Layout layout;
    std::vector<float> depth, nx, ny, nz, gradX, gradY;  // normals of unit length
    std::vector<float> geometry;                         // 1 on geometry, 0 on sky and in the margins
    std::vector<float> footprint;                        // per-pixel reach in pixels; empty = unlimited

    // Fills the planes from the guides; reuses the allocations of a previous call.
    void assign(const GuideBuffers& g, const std::vector<vec2>& grad, std::span<const float> footprintPx,
                const Layout& l) {
        const bool relayout = !(l == layout);
        layout = l;
        for (std::vector<float>* plane : {&depth, &nx, &ny, &nz, &gradX, &gradY, &geometry})
            fitPlane(*plane, l, relayout);
        forEachRow(l, [&](int, int, std::size_t k, std::size_t i) {
            const bool sky = g.isSky(i);
            geometry[k] = sky ? 0.f : 1.f;
            depth[k] = sky ? 0.f : detail::clampNaNLow(g.depth[i], -kMaxRadiance, kMaxRadiance);
            const vec3 n = sky ? vec3(0.f) : detail::guideUnitNormal(g.normal[i]);
            nx[k] = n.x, ny[k] = n.y, nz[k] = n.z;
            gradX[k] = sky ? 0.f : sanitize(grad[i].x);
            gradY[k] = sky ? 0.f : sanitize(grad[i].y);
        });
        footprint.clear();
        if (!footprintPx.empty()) {
            fitPlane(footprint, l, true);
            forEachRow(l, [&](int, int, std::size_t k, std::size_t i) {
                footprint[k] = footprintPx[i] > 0.f ? footprintPx[i] : 0.f;
            });
        }
    }
};

// The signal as structure-of-arrays floats (colour sanitised, variance
// clamped), in the guides' layout, with its luminance.
struct SignalPlanes {
    Layout layout;
    std::vector<float> r, g, b, variance, luminance;
    // Every pixel has r == g == b (AO, shadow visibility): the taps
    // accumulate r alone and store it to all three, the same bits as three
    // equal sums. An iteration keeps it so (one weight for all channels).
    bool grey = false;
    void fit(const Layout& l) {
        const bool relayout = !(l == layout);
        layout = l;
        for (std::vector<float>* plane : {&r, &g, &b, &variance, &luminance}) fitPlane(*plane, l, relayout);
    }
};

// The edge-stopping weight of a tap is 2^-E, E = log2(e) (sigmaN (1 - n.n')
// + |z - z'| / (sigmaZ |grad z . offset| + eps |z|) + |l - l'| / (sigmaL
// sqrt(g3x3(Var)) + eps)), computed as a float whose bits are 127 * 2^23 -
// E * 2^23 (Schraudolph 1999): 2^-floor(E) (1 - frac(E) / 2), within
// +6.2 % / -0 % of 2^-E, exactly 1 for E = 0 and exactly 0 for E >= 127.
// Every term is scaled by 2^23 at the pixel, so a tap costs one
// sum, a clamp and a conversion to integer instead of an exp.
constexpr float kExpUnit = 8388608.f;           // 2^23: one unit of E in the float's bits
constexpr float kLog2e = 1.44269504088896341f;  // exp(-x) = 2^(-x log2(e))
constexpr float kMaxBits = 127.f * kExpUnit;    // the bits of 1.0f

// An iteration's task filters kRowGroup rows, step apart, in runs of kRun pixels (see iterate()).
constexpr int kRowGroup = 8;
constexpr int kRun = 256;  // a multiple of the vector widths

// A run of one row's pixels: per vector of pixels, the centre and its 24
// off-centre taps (12 pairs at +-offset sharing the depth term's
// denominator), accumulated in registers, then normalised and stored.
struct TapRow {
    const float *nx, *ny, *nz, *depth, *gradX, *gradY, *geometry, *footprint, *lum, *var, *red, *green, *blue;
    float *outR, *outG, *outB, *outVar, *outLum;
    int w, h, y, step, stride;
    int x0, x1;         // the run: pixels [x0, x1), x0 a multiple of the vector width, at most kRun
    std::size_t row;    // plane index of the row's pixel 0
    float normalScale;  // sigmaN log2(e) 2^23 (the centre's normal is scaled by it)
    float bias;  // 127 2^23 - normalScale: the weight's bits are bias + n.n' normalScale - depth and luminance terms
    float gradScale;   // sigmaZ * step
    float planeScale;  // step with AtrousParams::depthFromPlane, else 0: the centre's depth moves along its gradient
    float depthEps;
    float sigmaL, luminanceEps;
};

// sqrt(x) for x >= 0 by Newton-Raphson on 1/sqrt(max(x, 1e-30)) (three
// steps from the bit-trick estimate: relative error < 1e-6), times x.
template <int N>
RTLAB_SIMD_INLINE simd::vfloat<N> sqrtNonNegative(const simd::vfloat<N>& x) {
    using V = simd::vfloat<N>;
    const V xc = simd::select<N>(x > 1e-30f, x, simd::splat<N>(1e-30f));
    V r = (V)(0x5f3759df - ((simd::vint<N>)xc >> 1));
    const V half = xc * 0.5f;
    r = r * (1.5f - half * r * r);
    r = r * (1.5f - half * r * r);
    r = r * (1.5f - half * r * r);
    return x * r;
}

// Grey: the signal's channels are equal (SignalPlanes::grey); one colour sum.
// GateSky: the normal term does not zero a sky tap by itself (sigmaN log2(e)
// < 127), so the weight is multiplied by the tap's geometry flag. Checked: a
// step beyond the layout's fastReach: rows outside the image and taps with
// |dx| >= width are skipped.
template <int N, bool GateSky, bool Checked, bool Grey>
RTLAB_SIMD_INLINE void filterRow(const TapRow& t) {
    using V = simd::vfloat<N>;
    using VI = simd::vint<N>;
    const int w = t.w;
    const float hCentre = kKernel[0] * kKernel[0];
    const float reach = 2.f * static_cast<float>(t.step);
    VI laneIndex;
    for (int lane = 0; lane < N; ++lane) laneIndex[lane] = lane;
    const V zero = simd::opaque<N>(simd::splat<N>(0.f)), minDen = simd::opaque<N>(simd::splat<N>(1e-30f));
    // log2 of 1/h for |offset| 0, 1, 2 per axis: 3/8 = 3/2 2^-2, 1/4 = 2^-2, 1/16 = 2^-4.
    constexpr int kShift[3] = {2, 2, 4};
    // The bias less k 2^23 for the taps' k = 4, 6, 8 (kShift[|kx|] + kShift[|ky|]).
    V biasOf[3];
    for (int b = 0; b < 3; ++b) biasOf[b] = simd::splat<N>(t.bias - static_cast<float>(4 + 2 * b) * kExpUnit);
    // Pass 1, per vector of the run: which pixels are filtered, the luminance scale and the
    // depth term's 12 reciprocals (a long chain of latencies: the blur, the square root and
    // the divisions), kept in L1 so that the taps of pass 2 do not wait for them.
    constexpr int kVectors = kRun / N;
    V cILs[kVectors], rZs[kVectors][12];
    VI actives[kVectors];
    for (int x = t.x0, v = 0; x < t.x1; x += N, ++v) {
        const std::size_t i = t.row + static_cast<std::size_t>(x);
        // Which of these pixels this iteration filters (geometry, within the footprint, inside the row).
        VI active = simd::loadu<N>(t.geometry + i) != 0.f;
        if (t.footprint) active &= simd::splat<N>(reach) <= simd::loadu<N>(t.footprint + i);
        if (w - x < N) active &= laneIndex < (w - x);
        actives[v] = active;
        if (rtlab::simd::signMask<N>(active) == 0u) continue;
        // The luminance scale log2(e) 2^23 / (sigmaL sqrt(g3x3(Var)) + eps), the 3x3
        // Gaussian of the variance over geometry pixels (sky and the margins add 0 to both sums).
        V sum = simd::splat<N>(0.f), weight = simd::splat<N>(0.f);
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const std::size_t j = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(i) + dy * t.stride + dx);
                const V kw = simd::loadu<N>(t.geometry + j) * ((dx == 0 ? 0.5f : 0.25f) * (dy == 0 ? 0.5f : 0.25f));
                sum = sum + kw * simd::loadu<N>(t.var + j);
                weight = weight + kw;
            }
        const V blurred = simd::select<N>(
            weight > 0.f, sum / simd::select<N>(weight > 0.f, weight, simd::splat<N>(1.f)), simd::splat<N>(0.f));
        const V lumDen = sqrtNonNegative<N>(blurred) * t.sigmaL + t.luminanceEps;
        // Finite, so that equal luminances give the term 0 (0 * inf would be NaN).
        cILs[v] = simd::select<N>(lumDen > 0.f,
                                  simd::min<N>(simd::splat<N>(kLog2e * kExpUnit) / lumDen, simd::splat<N>(3e38f)),
                                  simd::splat<N>(3e38f));
        // The depth term's reciprocal denominators log2(e) 2^23 / max(sigmaZ |grad . offset| + eps |z|, 1e-30)
        // for the 12 offsets (kx, ky) with ky > 0 or ky = 0 < kx (the other 12 are their negatives).
        const V gA = simd::loadu<N>(t.gradX + i) * t.gradScale, gB = simd::loadu<N>(t.gradY + i) * t.gradScale;
        const V gA2 = gA + gA, gB2 = gB + gB;
        const V eps = simd::abs<N>(simd::loadu<N>(t.depth + i)) * t.depthEps;
        const V along[12] = {gA,       gA2,       gB - gA2, gB - gA, gB,       gB + gA,
                             gB + gA2, gB2 - gA2, gB2 - gA, gB2,     gB2 + gA, gB2 + gA2};
        for (int k = 0; k < 12; ++k) {
            const V den = simd::abs<N>(along[k]) + eps;
            rZs[v][k] = simd::splat<N>(kLog2e * kExpUnit) / simd::max<N>(den, minDen);
        }
    }
    // Pass 2, per vector: the centre and its 24 taps.
    for (int x = t.x0, v = 0; x < t.x1; x += N, ++v) {
        const std::size_t i = t.row + static_cast<std::size_t>(x);
        const V cR = simd::loadu<N>(t.red + i);
        const V cG = Grey ? cR : simd::loadu<N>(t.green + i), cB = Grey ? cR : simd::loadu<N>(t.blue + i);
        const V cVar = simd::loadu<N>(t.var + i), cLum = simd::loadu<N>(t.lum + i);
        const VI active = actives[v];
        if (rtlab::simd::signMask<N>(active) == 0u) {
            simd::storeu<N>(t.outR + i, cR), simd::storeu<N>(t.outG + i, cG), simd::storeu<N>(t.outB + i, cB);
            simd::storeu<N>(t.outVar + i, cVar), simd::storeu<N>(t.outLum + i, cLum);
            continue;
        }
        const V cIL = cILs[v], cDepth = simd::loadu<N>(t.depth + i);
        // The depth gradient per step (0 without depthFromPlane: the centre's depth as it is).
        const V pA = simd::loadu<N>(t.gradX + i) * t.planeScale, pB = simd::loadu<N>(t.gradY + i) * t.planeScale;
        const V* rZ = rZs[v];
        const V cx = simd::loadu<N>(t.nx + i) * t.normalScale, cy = simd::loadu<N>(t.ny + i) * t.normalScale,
                cz = simd::loadu<N>(t.nz + i) * t.normalScale;
        V sW = simd::splat<N>(hCentre), sVar = cVar * (hCentre * hCentre), sR = cR * hCentre, sG = cG * hCentre,
          sB = cB * hCentre;
        // A tap's kernel weight h = m 2^-k (m 1 or 3/2) is folded into the bits: 2^-k as k 2^23 less,
        // exact except that weights below 2^-(127-k) become 0.
        const auto tap = [&](std::ptrdiff_t offset, const V& rz, const V& bias, bool threeHalves,
                             const V& expectedDepth) __attribute__((always_inline)) {
            const std::size_t j = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(i) + offset);
            const V dot = cx * simd::loadu<N>(t.nx + j) + cy * simd::loadu<N>(t.ny + j) + cz * simd::loadu<N>(t.nz + j);
            const V eZ = simd::abs<N>(expectedDepth - simd::loadu<N>(t.depth + j)) * rz;
            const V eL = simd::abs<N>(cLum - simd::loadu<N>(t.lum + j)) * cIL;
            // The terms are >= 0 and finite or +inf: never NaN. Unit normals keep n.n' <= 1 up to
            // round-off, so the bits stay below those of 2^-k * (1 + 1e-5): no upper clamp.
            const V bits = simd::max<N>((dot + bias) - (eZ + eL), zero);
            V hw = (V) __builtin_convertvector(bits, VI);
            if constexpr (GateSky) hw = hw * simd::loadu<N>(t.geometry + j);
            if (threeHalves) hw = hw * 1.5f;
            sW = sW + hw;
            sVar = sVar + hw * hw * simd::loadu<N>(t.var + j);
            sR = sR + hw * simd::loadu<N>(t.red + j);
            if constexpr (!Grey) {
                sG = sG + hw * simd::loadu<N>(t.green + j);
                sB = sB + hw * simd::loadu<N>(t.blue + j);
            }
        };
        constexpr int kOffsets[12][2] = {{1, 0}, {2, 0},  {-2, 1}, {-1, 1}, {0, 1}, {1, 1},
                                         {2, 1}, {-2, 2}, {-1, 2}, {0, 2},  {1, 2}, {2, 2}};
#pragma GCC unroll 12
        for (int k = 0; k < 12; ++k) {
            const int kx = kOffsets[k][0], ky = kOffsets[k][1], ax = kx < 0 ? -kx : kx;
            const V& bias = biasOf[(kShift[ax] + kShift[ky] - 4) / 2];
            const bool threeHalves = ax == 0 || ky == 0;  // exactly one factor 3/8
            const int dx = kx * t.step, dy = ky * t.step;
            const std::ptrdiff_t offset = static_cast<std::ptrdiff_t>(dy) * t.stride + dx;
            // The centre's depth moved to the tap along its gradient (+0 or -0 without
            // depthFromPlane: the same bits as cDepth after the subtraction's abs).
            const V along = pA * static_cast<float>(kx) + pB * static_cast<float>(ky);
            const V ahead = cDepth + along, behind = cDepth - along;
            if constexpr (Checked) {
                if (dx >= w || -dx >= w) continue;  // no pixel of the row: all in the margin
                if (t.y + dy < t.h) tap(offset, rZ[k], bias, threeHalves, ahead);
                if (t.y - dy >= 0) tap(-offset, rZ[k], bias, threeHalves, behind);
            } else {
                tap(offset, rZ[k], bias, threeHalves, ahead);
                tap(-offset, rZ[k], bias, threeHalves, behind);
            }
        }
        const V inv = 1.f / sW;
        const V oR = sR * inv, oG = Grey ? oR : sG * inv, oB = Grey ? oR : sB * inv;
        V oVar = sVar * inv * inv;  // > 0 and finite, or +inf: clamped to kMaxVariance
        oVar = simd::select<N>(oVar > 0.f, simd::min<N>(oVar, simd::splat<N>(kMaxVariance)), simd::splat<N>(0.f));
        const V oLum = oR * 0.2126f + oG * 0.7152f + oB * 0.0722f;  // luminance(), lane-wise
        simd::storeu<N>(t.outR + i, simd::select<N>(active, oR, cR));
        simd::storeu<N>(t.outG + i, simd::select<N>(active, oG, cG));
        simd::storeu<N>(t.outB + i, simd::select<N>(active, oB, cB));
        simd::storeu<N>(t.outVar + i, simd::select<N>(active, oVar, cVar));
        simd::storeu<N>(t.outLum + i, simd::select<N>(active, oLum, cLum));
    }
}

// The same, compiled for AVX2 (picked at run time by simd::preferredWidth).
template <bool GateSky, bool Checked, bool Grey>
__attribute__((target("avx2"))) void filterRowAvx2(const TapRow& t) {
    filterRow<8, GateSky, Checked, Grey>(t);
}

template <bool GateSky, bool Checked, bool Grey>
void filterRowOfWidth(const TapRow& t, bool avx2) {
    if (avx2) filterRowAvx2<GateSky, Checked, Grey>(t);
    else filterRow<4, GateSky, Checked, Grey>(t);
}

void filterRowAny(const TapRow& t, bool avx2, bool gateSky, bool checked, bool grey) {
    if (grey) {
        if (gateSky)
            checked ? filterRowOfWidth<true, true, true>(t, avx2) : filterRowOfWidth<true, false, true>(t, avx2);
        else checked ? filterRowOfWidth<false, true, true>(t, avx2) : filterRowOfWidth<false, false, true>(t, avx2);
    } else {
        if (gateSky)
            checked ? filterRowOfWidth<true, true, false>(t, avx2) : filterRowOfWidth<true, false, false>(t, avx2);
        else checked ? filterRowOfWidth<false, true, false>(t, avx2) : filterRowOfWidth<false, false, false>(t, avx2);
    }
}

// One iteration with step `step` from `in` to `out` (in.luminance is current).
void iterate(const GuidePlanes& g, const SignalPlanes& in, int step, const AtrousParams& p, SignalPlanes& out) {
    const Layout& l = g.layout;
    out.fit(l);
    out.grey = in.grey;
    const float sigmaN = p.sigmaN > 0.f ? std::min(p.sigmaN, 1e6f) : 0.f;
    const float normalScale = sigmaN * kLog2e * kExpUnit;
    const float bias = kMaxBits - normalScale;
    const bool gateSky = bias > 0.f;  // a zero normal gives bits <= bias
    const bool checked = 2L * step > l.fastReach;
    const bool avx2 = simd::preferredWidth() == 8;
    const float sigmaZ = p.sigmaZ > 0.f ? p.sigmaZ : 0.f;
    const float sigmaL = p.sigmaL > 0.f ? p.sigmaL : 0.f;
    const float lumEps = p.luminanceEpsilon > 0.f ? p.luminanceEpsilon : 0.f;
    const float depthEps = p.depthEpsilon > 0.f ? p.depthEpsilon : 0.f;
    const TapRow common{g.nx.data(),
                        g.ny.data(),
                        g.nz.data(),
                        g.depth.data(),
                        g.gradX.data(),
                        g.gradY.data(),
                        g.geometry.data(),
                        g.footprint.empty() ? nullptr : g.footprint.data(),
                        in.luminance.data(),
                        in.variance.data(),
                        in.r.data(),
                        in.g.data(),
                        in.b.data(),
                        out.r.data(),
                        out.g.data(),
                        out.b.data(),
                        out.variance.data(),
                        out.luminance.data(),
                        l.width,
                        l.height,
                        0,
                        step,
                        l.stride,
                        0,
                        0,
                        0,
                        normalScale,
                        bias,
                        sigmaZ * static_cast<float>(step),
                        p.depthFromPlane ? static_cast<float>(step) : 0.f,
                        depthEps,
                        sigmaL,
                        lumEps};
    // One task per kRowGroup rows y0 + k step: consecutive ones share 4 of their 5 tap rows, so
    // the runs of kRun pixels of the group's rows, filtered one after the other, find the shared
    // taps in L1/L2 (one row after the other, the tap rows of steps >= 4 fell out of L2 between
    // their uses). 8 rows and 256 pixels measured fastest of 2-8 rows and 64-512 pixels.
    const std::size_t span = static_cast<std::size_t>(kRowGroup) * static_cast<std::size_t>(step);
    const std::size_t blocks = (static_cast<std::size_t>(l.height) + span - 1) / span;
    parallelForEach(blocks * static_cast<std::size_t>(step), [&](std::size_t task) {
        const std::size_t s = static_cast<std::size_t>(step);
        const int y0 = static_cast<int>(task / s * span + task % s);
        for (int x0 = 0; x0 < l.width; x0 += kRun)
            for (int y = y0; y < std::min(y0 + kRowGroup * step, l.height); y += step) {
                TapRow t = common;
                t.y = y, t.x0 = x0, t.x1 = std::min(x0 + kRun, l.width), t.row = l.at(0, y);
                filterRowAny(t, avx2, gateSky, checked, in.grey);
            }
    });
}

void loadSignal(std::span<const vec3> color, std::span<const float> variance, const Layout& l, SignalPlanes& s) {
    s.fit(l);
    std::vector<std::uint8_t> colouredRow(static_cast<std::size_t>(l.height), 0);
    forEachRow(l, [&](int, int y, std::size_t k, std::size_t i) {
        const vec3 c = sanitize(color[i]);
        s.r[k] = c.r, s.g[k] = c.g, s.b[k] = c.b;
        s.variance[k] = clampVariance(variance[i]);
        s.luminance[k] = luminance(c);
        // Bit-equal channels (-0 and +0 differ: the grey path would store r's sign to all three).
        if (std::bit_cast<std::uint32_t>(c.r) != std::bit_cast<std::uint32_t>(c.g) ||
            std::bit_cast<std::uint32_t>(c.r) != std::bit_cast<std::uint32_t>(c.b))
            colouredRow[static_cast<std::size_t>(y)] = 1;
    });
    s.grey = std::none_of(colouredRow.begin(), colouredRow.end(), [](std::uint8_t c) { return c != 0; });
}

void storeColor(const SignalPlanes& s, std::span<vec3> out) {
    forEachRow(s.layout, [&](int, int, std::size_t k, std::size_t i) { out[i] = vec3(s.r[k], s.g[k], s.b[k]); });
}
void storeVariance(const SignalPlanes& s, std::span<float> out) {
    forEachRow(s.layout, [&](int, int, std::size_t k, std::size_t i) { out[i] = s.variance[k]; });
}

}  // namespace

struct AtrousWorkspace::Buffers {
    std::vector<vec2> gradient;
    GuidePlanes guides;
    SignalPlanes a, b;
};

AtrousWorkspace::AtrousWorkspace() : buffers_(std::make_unique<Buffers>()) {}
AtrousWorkspace::~AtrousWorkspace() = default;
AtrousWorkspace::AtrousWorkspace(AtrousWorkspace&&) noexcept = default;
AtrousWorkspace& AtrousWorkspace::operator=(AtrousWorkspace&&) noexcept = default;

void atrousIteration(const GuideBuffers& g, std::span<const vec3> color, std::span<const float> variance, int step,
                     const AtrousParams& params, std::span<vec3> colorOut, std::span<float> varianceOut,
                     std::span<const float> footprintPx) {
    AtrousWorkspace workspace;
    AtrousWorkspace::Buffers& w = *workspace.buffers_;
    const std::vector<vec2>& grad = detail::gradientOf(g, w.gradient);
    checkInputs(g, color, variance, colorOut, varianceOut);
    if (!footprintPx.empty()) detail::checkSize(footprintPx.size(), g.pixelCount(), "atrous: footprintPx");
    const int s = std::clamp(step, 1, 1 << 20);
    const Layout layout = Layout::of(g.width, g.height, s);
    w.guides.assign(g, grad, footprintPx, layout);
    loadSignal(color, variance, layout, w.a);
    iterate(w.guides, w.a, s, params, w.b);
    storeColor(w.b, colorOut);
    storeVariance(w.b, varianceOut);
}

void atrousFilter(const GuideBuffers& g, std::span<const vec3> color, std::span<const float> variance,
                  const AtrousParams& params, std::span<vec3> colorOut, std::span<float> varianceOut, int tapIterations,
                  std::span<vec3> tapColor, std::span<const float> footprintPx, AtrousWorkspace* workspace) {
    AtrousWorkspace local;
    AtrousWorkspace::Buffers& w = *(workspace ? workspace : &local)->buffers_;
    const std::vector<vec2>& grad = detail::gradientOf(g, w.gradient);
    checkInputs(g, color, variance, colorOut, varianceOut);
    const std::size_t n = g.pixelCount();
    if (!tapColor.empty()) detail::checkSize(tapColor.size(), n, "atrous: tapColor");
    if (!footprintPx.empty()) detail::checkSize(footprintPx.size(), n, "atrous: footprintPx");
    const int iterations = params.iterations > 0 ? params.iterations : 0;
    const int tap = std::clamp(tapIterations, 0, iterations);
    if (iterations == 0) {  // documented: plain copies
        std::copy(color.begin(), color.end(), colorOut.begin());
        std::copy(variance.begin(), variance.end(), varianceOut.begin());
        if (!tapColor.empty()) std::copy(color.begin(), color.end(), tapColor.begin());
        return;
    }

    const Layout layout = Layout::of(g.width, g.height, 1 << std::min(iterations - 1, 20));
    w.guides.assign(g, grad, footprintPx, layout);
    loadSignal(color, variance, layout, w.a);
    if (!tapColor.empty() && tap == 0) std::copy(color.begin(), color.end(), tapColor.begin());
    for (int it = 0; it < iterations; ++it) {
        iterate(w.guides, w.a, 1 << std::min(it, 20), params, w.b);
        std::swap(w.a, w.b);
        if (!tapColor.empty() && it + 1 == tap) storeColor(w.a, tapColor);
    }
    storeColor(w.a, colorOut);
    storeVariance(w.a, varianceOut);
}

}  // namespace rtlab::denoise
