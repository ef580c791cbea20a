#include <rtlab/denoise/atrous.hpp>

#include "detail.hpp"
#include "simd.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace rtlab::denoise {

namespace {

constexpr int kLanes = simd::kMaxWidth;  // padding after the planes' last pixel

constexpr float kKernel[3] = {3.f / 8.f, 1.f / 4.f, 1.f / 16.f};
// Input variances are clamped to this so that sum h^2 w^2 Var over 25 taps,
// divided by (sum h w)^2 >= (9/64)^2, stays a finite float.
constexpr float kMaxVariance = 1e36f;

float clampVariance(float v) { return v > 0.f ? (v < kMaxVariance ? v : kMaxVariance) : 0.f; }
float toFloatVariance(float v) {
    if (!(v > 0.f)) return 0.f;
    return v < 3.0e38f ? v : 3.0e38f;
}

void checkInputs(const GuideBuffers& g, std::span<const vec3> color, std::span<const float> variance,
                 std::span<vec3> colorOut, std::span<float> varianceOut) {
    const std::size_t n = g.pixelCount();
    detail::checkSize(color.size(), n, "atrous: color");
    detail::checkSize(variance.size(), n, "atrous: variance");
    detail::checkSize(colorOut.size(), n, "atrous: colorOut");
    detail::checkSize(varianceOut.size(), n, "atrous: varianceOut");
}

// The planes' layout: rows of `stride` floats, each with `margin` zero floats
// on both sides, so that a tap up to margin - kLanes pixels left or right of
// any pixel of a vector reads a zero (geometry 0: weight 0) instead of another
// row or memory outside the planes. The margins are zeroed when the layout
// changes and never written after.
struct Layout {
    int width = 0, height = 0, margin = 0, stride = 0;
    std::size_t size() const { return static_cast<std::size_t>(height + 1) * static_cast<std::size_t>(stride) + kLanes; }
    std::size_t at(int x, int y) const {
        return static_cast<std::size_t>(y) * static_cast<std::size_t>(stride) + static_cast<std::size_t>(margin + x);
    }
    bool operator==(const Layout&) const = default;
    // The margin for taps up to 2 * maxStep pixels away (a tap |dx| >= width
    // reaches no pixel of the row and is skipped).
    static Layout of(int w, int h, int maxStep) {
        Layout l;
        l.width = w;
        l.height = h;
        const long reach = std::min<long>(2L * maxStep, static_cast<long>(w));
        l.margin = static_cast<int>((reach + kLanes + kLanes - 1) / kLanes * kLanes);
        l.stride = w + 2 * l.margin;
        return l;
    }
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
    std::vector<float> depth, nx, ny, nz, gradX, gradY;
    std::vector<float> geometry;  // 1 on geometry, 0 on sky and in the margins
    std::vector<float> footprint; // per-pixel reach in pixels; empty = unlimited

    // Fills the planes from the guides; reuses the allocations of a previous call.
    void assign(const GuideBuffers& g, const std::vector<vec2>& grad, std::span<const float> footprintPx,
                const Layout& l) {
        const bool relayout = !(l == layout);
        layout = l;
        for (std::vector<float>* plane : {&depth, &nx, &ny, &nz, &gradX, &gradY, &geometry}) fitPlane(*plane, l, relayout);
        forEachRow(l, [&](int, int, std::size_t k, std::size_t i) {
            const bool sky = g.isSky(i);
            geometry[k] = sky ? 0.f : 1.f;
            depth[k] = sky ? 0.f : detail::clampNaNLow(g.depth[i], -kMaxRadiance, kMaxRadiance);
            nx[k] = sky ? 0.f : sanitize(g.normal[i].x);
            ny[k] = sky ? 0.f : sanitize(g.normal[i].y);
            nz[k] = sky ? 0.f : sanitize(g.normal[i].z);
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
    void fit(const Layout& l) {
        const bool relayout = !(l == layout);
        layout = l;
        for (std::vector<float>* plane : {&r, &g, &b, &variance, &luminance}) fitPlane(*plane, l, relayout);
    }
};

// One row's pixels: per vector of pixels, the centre and its 24 off-centre
// taps, accumulated in registers, then normalised and stored.
struct TapRow {
    const float *nx, *ny, *nz, *depth, *gradX, *gradY, *geometry, *footprint, *lum, *invLum, *var, *red, *green,
        *blue;
    float *outR, *outG, *outB, *outVar, *outLum;
    int w, h, y, step, stride;
    std::size_t row;  // plane index of the row's pixel 0
    float sigmaZ, depthEps;
    const simd::NormalPower* normalPower;
    bool normalGatesSky;  // sigmaN > 0: max(0, n.n')^sigmaN is 0 for a zero normal
};

// Sq >= 0: sigmaN = 2^Sq, the normal weight as Sq squarings unrolled at
// compile time (the paper's 128: 7); -1: NormalPower's general path.
template <int N, int Sq>
RTLAB_SIMD_INLINE void filterRow(const TapRow& t) {
    using V = simd::vfloat<N>;
    const int w = t.w;
    const float hCentre = kKernel[0] * kKernel[0];
    const float reach = 2.f * static_cast<float>(t.step);
    for (int x = 0; x < w; x += N) {
        const int lanes = std::min(N, w - x);
        const std::size_t i = t.row + static_cast<std::size_t>(x);
        // Which of these pixels this iteration filters (geometry, within the footprint).
        bool any = false;
        for (int lane = 0; lane < lanes; ++lane)
            any = any || (t.geometry[i + lane] != 0.f && (!t.footprint || reach <= t.footprint[i + lane]));
        if (!any) {
            for (int lane = 0; lane < lanes; ++lane) {
                t.outR[i + lane] = t.red[i + lane], t.outG[i + lane] = t.green[i + lane];
                t.outB[i + lane] = t.blue[i + lane], t.outVar[i + lane] = t.var[i + lane];
                t.outLum[i + lane] = t.lum[i + lane];
            }
            continue;
        }
        const V cx = simd::loadu<N>(t.nx + i), cy = simd::loadu<N>(t.ny + i), cz = simd::loadu<N>(t.nz + i);
        const V cDepth = simd::loadu<N>(t.depth + i), cGx = simd::loadu<N>(t.gradX + i),
                cGy = simd::loadu<N>(t.gradY + i);
        const V cLum = simd::loadu<N>(t.lum + i), cInvLum = simd::loadu<N>(t.invLum + i);
        const V cDepthEps = simd::abs<N>(cDepth) * t.depthEps;
        const V cVar = simd::loadu<N>(t.var + i);
        const V cR = simd::loadu<N>(t.red + i), cG = simd::loadu<N>(t.green + i), cB = simd::loadu<N>(t.blue + i);
        V sW = simd::splat<N>(hCentre), sVar = cVar * (hCentre * hCentre), sR = cR * hCentre, sG = cG * hCentre,
          sB = cB * hCentre;
        for (int ky = -2; ky <= 2; ++ky) {
            const int py = t.y + ky * t.step;
            if (py < 0 || py >= t.h) continue;
            const std::ptrdiff_t rowOffset = static_cast<std::ptrdiff_t>(ky) * t.step * t.stride;
            for (int kx = -2; kx <= 2; ++kx) {
                if (kx == 0 && ky == 0) continue;
                const int dx = kx * t.step;
                if (dx >= w || -dx >= w) continue;  // no pixel of the row: all in the margin
                const float hk = kKernel[kx < 0 ? -kx : kx] * kKernel[ky < 0 ? -ky : ky];
                const std::size_t j = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(i) + rowOffset + dx);
                // Edge-stopping weight: normal^sigmaN * exp(-(depth term + luminance term)), 0 on sky taps
                // and in the margins.
                const V dot = cx * simd::loadu<N>(t.nx + j) + cy * simd::loadu<N>(t.ny + j) + cz * simd::loadu<N>(t.nz + j);
                V wn;
                if constexpr (Sq >= 0) {
                    wn = simd::min<N>(simd::positiveOrZero<N>(dot), simd::splat<N>(1.f));
                    for (int k = 0; k < Sq; ++k) wn *= wn;
                } else {
                    wn = t.normalPower->apply<N>(dot);
                }
                // The depth term |z - z'| / (sigmaZ |grad . offset| + eps |z|) with the denominator raised
                // to 1e-30 (equal depths give 0; a zero denominator a term >= 87, i.e. weight 0, as +inf did).
                const V zDen = simd::abs<N>(cGx * static_cast<float>(dx) + cGy * static_cast<float>(ky * t.step)) *
                                   t.sigmaZ + cDepthEps;
                const V termZ = simd::abs<N>(cDepth - simd::loadu<N>(t.depth + j)) /
                                simd::select<N>(zDen > 1e-30f, zDen, simd::splat<N>(1e-30f));
                const V dl = simd::abs<N>(cLum - simd::loadu<N>(t.lum + j));
                const V termL = dl * cInvLum;  // the scale is finite: 0 for equal luminances
                // A sky tap or a margin has normal 0, so wn = 0 already unless sigmaN = 0.
                const V e = simd::expNegWeight<N>(termZ + termL) * wn;
                const V wgt = t.normalGatesSky ? e : e * simd::loadu<N>(t.geometry + j);
                const V hw = wgt * hk;
                sW = sW + hw;
                sVar = sVar + hw * hw * simd::loadu<N>(t.var + j);
                sR = sR + hw * simd::loadu<N>(t.red + j);
                sG = sG + hw * simd::loadu<N>(t.green + j);
                sB = sB + hw * simd::loadu<N>(t.blue + j);
            }
        }
        const V inv = 1.f / sW;
        const V oR = sR * inv, oG = sG * inv, oB = sB * inv, oVar = sVar * inv * inv;
        for (int lane = 0; lane < lanes; ++lane) {
            const std::size_t k = i + lane;
            if (t.geometry[k] == 0.f || (t.footprint && !(reach <= t.footprint[k]))) {
                t.outR[k] = t.red[k], t.outG[k] = t.green[k], t.outB[k] = t.blue[k];
                t.outVar[k] = t.var[k];
                t.outLum[k] = t.lum[k];
                continue;
            }
            t.outR[k] = oR[lane], t.outG[k] = oG[lane], t.outB[k] = oB[lane];
            t.outVar[k] = clampVariance(toFloatVariance(oVar[lane]));
            t.outLum[k] = luminance(vec3(oR[lane], oG[lane], oB[lane]));
        }
    }
}

// The same, compiled for AVX2 (picked at run time by simd::preferredWidth).
__attribute__((target("avx2"))) void filterRowAvx2(const TapRow& t) { filterRow<8, -1>(t); }
__attribute__((target("avx2"))) void filterRowAvx2Sq7(const TapRow& t) { filterRow<8, 7>(t); }

// One iteration with step `step` from `in` to `out` (in.luminance is current).
void iterate(const GuidePlanes& g, const SignalPlanes& in, int step, const AtrousParams& p,
             std::vector<float>& invLumScale, SignalPlanes& out) {
    const Layout& l = g.layout;
    const int w = l.width, h = l.height;
    out.fit(l);
    fitPlane(invLumScale, l, invLumScale.size() != l.size());
    // Step: the luminance edge-stopping scale 1 / (sigmaL sqrt(g3x3(Var)) + eps),
    // the 3x3 Gaussian of the variance over geometry pixels (sky and the
    // margins add 0 to both sums).
    forEachRow(l, [&](int, int y, std::size_t k, std::size_t) {
        float sum = 0.f, weight = 0.f;
        for (int dy = -1; dy <= 1; ++dy) {
            if (y + dy < 0 || y + dy >= h) continue;
            const std::size_t rowK = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(k) + dy * l.stride);
            for (int dx = -1; dx <= 1; ++dx) {
                const std::size_t j = rowK + dx;
                const float kw = (dx == 0 ? 0.5f : 0.25f) * (dy == 0 ? 0.5f : 0.25f) * g.geometry[j];
                sum += kw * in.variance[j];
                weight += kw;
            }
        }
        const float blurred = weight > 0.f ? sum / weight : 0.f;
        const float den = p.sigmaL * std::sqrt(blurred) + p.luminanceEpsilon;
        // Finite, so that equal luminances give the term 0 without a select; a
        // zero denominator gives a term >= 87 (weight 0) for any difference
        // above 3e-37, as +inf did for any difference.
        invLumScale[k] = den > 0.f ? std::min(1.f / den, 3e38f) : 3e38f;
    });

    const simd::NormalPower normalPower(p.sigmaN);
    const bool avx2 = simd::preferredWidth() == 8;
    const bool sq7 = normalPower.squarings == 7;
    parallelForEach(static_cast<std::size_t>(h), [&](std::size_t rowIndex) {
        const int y = static_cast<int>(rowIndex);
        const TapRow t{g.nx.data(), g.ny.data(), g.nz.data(), g.depth.data(), g.gradX.data(), g.gradY.data(),
                       g.geometry.data(), g.footprint.empty() ? nullptr : g.footprint.data(), in.luminance.data(),
                       invLumScale.data(), in.variance.data(), in.r.data(), in.g.data(), in.b.data(), out.r.data(),
                       out.g.data(), out.b.data(), out.variance.data(), out.luminance.data(), w, h, y, step,
                       l.stride, l.at(0, y), p.sigmaZ, p.depthEpsilon, &normalPower, normalPower.sigma > 0.f};
        if (sq7) {
            if (avx2) filterRowAvx2Sq7(t);
            else filterRow<4, 7>(t);
        } else {
            if (avx2) filterRowAvx2(t);
            else filterRow<4, -1>(t);
        }
    });
}

void loadSignal(std::span<const vec3> color, std::span<const float> variance, const Layout& l, SignalPlanes& s) {
    s.fit(l);
    forEachRow(l, [&](int, int, std::size_t k, std::size_t i) {
        const vec3 c = sanitize(color[i]);
        s.r[k] = c.r, s.g[k] = c.g, s.b[k] = c.b;
        s.variance[k] = clampVariance(variance[i]);
        s.luminance[k] = luminance(c);
    });
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
    std::vector<float> invLumScale;
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
    iterate(w.guides, w.a, s, params, w.invLumScale, w.b);
    storeColor(w.b, colorOut);
    storeVariance(w.b, varianceOut);
}

void atrousFilter(const GuideBuffers& g, std::span<const vec3> color, std::span<const float> variance,
                  const AtrousParams& params, std::span<vec3> colorOut, std::span<float> varianceOut,
                  int tapIterations, std::span<vec3> tapColor, std::span<const float> footprintPx,
                  AtrousWorkspace* workspace) {
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
        iterate(w.guides, w.a, 1 << std::min(it, 20), params, w.invLumScale, w.b);
        std::swap(w.a, w.b);
        if (!tapColor.empty() && it + 1 == tap) storeColor(w.a, tapColor);
    }
    storeColor(w.a, colorOut);
    storeVariance(w.a, varianceOut);
}

}  // namespace rtlab::denoise
