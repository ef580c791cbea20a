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

// The guides as structure-of-arrays floats, built once per filter call.
struct GuidePlanes {
    int width = 0, height = 0;
    std::vector<float> depth, nx, ny, nz, gradX, gradY;
    std::vector<float> geometry;  // 1 on geometry, 0 on sky
    std::vector<float> footprint; // per-pixel reach in pixels; empty = unlimited

    // Fills the planes from the guides; reuses the allocations of a previous call.
    void assign(const GuideBuffers& g, const std::vector<vec2>& grad, std::span<const float> footprintPx) {
        width = g.width;
        height = g.height;
        // kLanes floats of padding (zeros) after the last pixel: whole-vector loads never leave the arrays.
        const std::size_t n = g.pixelCount(), padded = n + kLanes;
        depth.resize(padded), nx.resize(padded), ny.resize(padded), nz.resize(padded);
        gradX.resize(padded), gradY.resize(padded), geometry.resize(padded);
        detail::forEachIndex(n, [&](std::size_t i) {
            const bool sky = g.isSky(i);
            geometry[i] = sky ? 0.f : 1.f;
            depth[i] = sky ? 0.f : detail::clampNaNLow(g.depth[i], -kMaxRadiance, kMaxRadiance);
            nx[i] = sky ? 0.f : sanitize(g.normal[i].x);
            ny[i] = sky ? 0.f : sanitize(g.normal[i].y);
            nz[i] = sky ? 0.f : sanitize(g.normal[i].z);
            gradX[i] = sky ? 0.f : sanitize(grad[i].x);
            gradY[i] = sky ? 0.f : sanitize(grad[i].y);
        });
        footprint.clear();
        if (!footprintPx.empty()) {
            footprint.resize(n);
            detail::forEachIndex(n, [&](std::size_t i) { footprint[i] = footprintPx[i] > 0.f ? footprintPx[i] : 0.f; });
        }
    }
};

// The signal as structure-of-arrays floats (colour sanitised, variance clamped).
struct SignalPlanes {
    std::vector<float> r, g, b, variance, luminance;
    // Sized n plus kLanes floats of zero padding (see GuidePlanes).
    void resize(std::size_t n) {
        const std::size_t padded = n + kLanes;
        r.resize(padded), g.resize(padded), b.resize(padded), variance.resize(padded), luminance.resize(padded);
    }
};

// One output row's 24 off-centre taps, accumulated into the row's sums.
struct TapRow {
    const float *nx, *ny, *nz, *depth, *gradX, *gradY, *geometry, *lum, *invLum, *var, *red, *green, *blue;
    float *sW, *sVar, *sR, *sG, *sB;
    const int* activeBefore;  // prefix count of the pixels this iteration filters
    int w, h, y, step;
    std::size_t row;
    float sigmaZ, depthEps;
    const simd::NormalPower* normalPower;
};

template <int N>
RTLAB_SIMD_INLINE void accumulateTaps(const TapRow& t) {
    using V = simd::vfloat<N>;
    const int w = t.w;
    for (int ky = -2; ky <= 2; ++ky) {
        const int py = t.y + ky * t.step;
        if (py < 0 || py >= t.h) continue;
        const std::size_t rowQ = static_cast<std::size_t>(py) * static_cast<std::size_t>(w);
        for (int kx = -2; kx <= 2; ++kx) {
            if (kx == 0 && ky == 0) continue;
            const int dx = kx * t.step;
            const int x0 = std::max(0, -dx), x1 = std::min(w, w - dx);
            if (x0 >= x1) continue;
            const float hk = kKernel[std::abs(kx)] * kKernel[std::abs(ky)];
            const V offX = simd::splat<N>(static_cast<float>(dx)), offY = simd::splat<N>(static_cast<float>(ky * t.step));
            for (int x = x0; x < x1; x += N) {
                if (t.activeBefore[std::min(x + N, w)] == t.activeBefore[x]) continue;
                // Lanes past x1 read padding or the next row and get weight 0.
                const V laneMask = x + N <= x1 ? simd::splat<N>(1.f) : simd::tailMask<N>(x1 - x);
                const std::size_t i = t.row + x, j = rowQ + x + dx;
                // Edge-stopping weight: normal^sigmaN * exp(-(depth term + luminance term)), 0 on sky taps.
                const V wn = t.normalPower->apply<N>(simd::normalDot<N>(t.nx, t.ny, t.nz, i, j));
                const V termZ = simd::depthTerm<N>(simd::loadu<N>(t.depth + i), simd::loadu<N>(t.depth + j),
                                                   simd::loadu<N>(t.gradX + i), simd::loadu<N>(t.gradY + i), offX,
                                                   offY, t.sigmaZ, t.depthEps);
                const V dl = simd::abs<N>(simd::loadu<N>(t.lum + i) - simd::loadu<N>(t.lum + j));
                const V termL = simd::select<N>(dl == 0.f, simd::splat<N>(0.f), dl * simd::loadu<N>(t.invLum + i));
                const V wgt = simd::expNeg<N>(termZ + termL) * wn * simd::loadu<N>(t.geometry + j);
                const V hw = wgt * (laneMask * hk);
                simd::storeu<N>(t.sW + x, simd::loadu<N>(t.sW + x) + hw);
                simd::storeu<N>(t.sVar + x, simd::loadu<N>(t.sVar + x) + hw * hw * simd::loadu<N>(t.var + j));
                simd::storeu<N>(t.sR + x, simd::loadu<N>(t.sR + x) + hw * simd::loadu<N>(t.red + j));
                simd::storeu<N>(t.sG + x, simd::loadu<N>(t.sG + x) + hw * simd::loadu<N>(t.green + j));
                simd::storeu<N>(t.sB + x, simd::loadu<N>(t.sB + x) + hw * simd::loadu<N>(t.blue + j));
            }
        }
    }
}

// The same, compiled for AVX2 (picked at run time by simd::preferredWidth).
__attribute__((target("avx2"))) void accumulateTapsAvx2(const TapRow& t) { accumulateTaps<8>(t); }

// One iteration with step `step` from `in` to `out`.
void iterate(const GuidePlanes& g, SignalPlanes& in, int step, const AtrousParams& p, std::vector<float>& invLumScale,
             SignalPlanes& out) {
    const int w = g.width, h = g.height;
    const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    // Step: luminance, and the luminance edge-stopping scale 1 / (sigmaL sqrt(g3x3(Var)) + eps).
    invLumScale.resize(n + kLanes);
    detail::forEachIndex(n, [&](std::size_t i) { in.luminance[i] = luminance(vec3(in.r[i], in.g[i], in.b[i])); });
    detail::forEachPixel(w, h, [&](int x, int y, std::size_t i) {
        float sum = 0.f, weight = 0.f;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const int px = x + dx, py = y + dy;
                if (px < 0 || py < 0 || px >= w || py >= h) continue;
                const std::size_t j = static_cast<std::size_t>(py) * static_cast<std::size_t>(w) + px;
                if (g.geometry[j] == 0.f) continue;
                const float k = (dx == 0 ? 0.5f : 0.25f) * (dy == 0 ? 0.5f : 0.25f);
                sum += k * in.variance[j];
                weight += k;
            }
        const float blurred = weight > 0.f ? sum / weight : 0.f;
        const float den = p.sigmaL * std::sqrt(blurred) + p.luminanceEpsilon;
        invLumScale[i] = den > 0.f ? 1.f / den : kInfinity;
    });

    const simd::NormalPower normalPower(p.sigmaN);
    const float hCentre = kKernel[0] * kKernel[0];
    const auto isFiltered = [&](std::size_t i) {
        return g.geometry[i] != 0.f && (g.footprint.empty() || 2.f * static_cast<float>(step) <= g.footprint[i]);
    };
    // Step: the 5x5 taps, row by row; per row, lanes are consecutive pixels.
    parallelForEach(static_cast<std::size_t>(h), [&](std::size_t rowIndex) {
        const int y = static_cast<int>(rowIndex);
        const std::size_t row = rowIndex * static_cast<std::size_t>(w);
        const std::size_t padded = static_cast<std::size_t>(w) + kLanes;
        std::vector<float> sumW(padded), sumVar(padded), sumR(padded), sumG(padded), sumB(padded);
        // Step: which pixels this iteration filters (geometry, within the footprint);
        // whole vectors of pixels it does not filter skip the taps.
        std::vector<int> activeBefore(static_cast<std::size_t>(w) + 1, 0);  // prefix count
        for (int x = 0; x < w; ++x) {
            const std::size_t i = row + x;
            activeBefore[x + 1] = activeBefore[x] + (isFiltered(i) ? 1 : 0);
        }
        if (activeBefore[w] == 0) {
            for (int x = 0; x < w; ++x) {
                const std::size_t i = row + x;
                out.r[i] = in.r[i], out.g[i] = in.g[i], out.b[i] = in.b[i];
                out.variance[i] = in.variance[i];
            }
            return;
        }
        for (int x = 0; x < w; ++x) {
            const std::size_t i = row + x;
            sumW[x] = hCentre;
            sumVar[x] = hCentre * hCentre * in.variance[i];
            sumR[x] = hCentre * in.r[i];
            sumG[x] = hCentre * in.g[i];
            sumB[x] = hCentre * in.b[i];
        }
        // Plain pointers: stores to the sums cannot alias them (the vectors' own pointers could be reloaded).
        const TapRow t{g.nx.data(), g.ny.data(), g.nz.data(), g.depth.data(), g.gradX.data(), g.gradY.data(),
                       g.geometry.data(), in.luminance.data(), invLumScale.data(), in.variance.data(), in.r.data(),
                       in.g.data(), in.b.data(), sumW.data(), sumVar.data(), sumR.data(), sumG.data(), sumB.data(),
                       activeBefore.data(), w, h, y, step, row, p.sigmaZ, p.depthEpsilon, &normalPower};
        if (simd::preferredWidth() == 8) accumulateTapsAvx2(t);
        else accumulateTaps<4>(t);
        // Step: normalise; sky centres pass through unchanged.
        for (int x = 0; x < w; ++x) {
            const std::size_t i = row + x;
            if (!isFiltered(i)) {
                out.r[i] = in.r[i], out.g[i] = in.g[i], out.b[i] = in.b[i];
                out.variance[i] = in.variance[i];
                continue;
            }
            const float inv = 1.f / sumW[x];
            out.r[i] = sumR[x] * inv;
            out.g[i] = sumG[x] * inv;
            out.b[i] = sumB[x] * inv;
            out.variance[i] = clampVariance(toFloatVariance(sumVar[x] * inv * inv));
        }
    });
}

void loadSignal(std::span<const vec3> color, std::span<const float> variance, SignalPlanes& s) {
    s.resize(color.size());
    detail::forEachIndex(color.size(), [&](std::size_t i) {
        const vec3 c = sanitize(color[i]);
        s.r[i] = c.r, s.g[i] = c.g, s.b[i] = c.b;
        s.variance[i] = clampVariance(variance[i]);
    });
}

void storeColor(const SignalPlanes& s, std::span<vec3> out) {
    detail::forEachIndex(out.size(), [&](std::size_t i) { out[i] = vec3(s.r[i], s.g[i], s.b[i]); });
}
void storeVariance(const SignalPlanes& s, std::span<float> out) {
    detail::forEachIndex(out.size(), [&](std::size_t i) { out[i] = s.variance[i]; });
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
    w.guides.assign(g, grad, footprintPx);
    loadSignal(color, variance, w.a);
    w.b.resize(g.pixelCount());
    iterate(w.guides, w.a, std::clamp(step, 1, 1 << 20), params, w.invLumScale, w.b);
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

    w.guides.assign(g, grad, footprintPx);
    loadSignal(color, variance, w.a);
    w.b.resize(n);
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
