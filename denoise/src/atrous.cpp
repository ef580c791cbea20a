#include <rtlab/denoise/atrous.hpp>

#include "detail.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace rtlab::denoise {

namespace {

constexpr float kKernel[3] = {3.f / 8.f, 1.f / 4.f, 1.f / 16.f};

float toFloatVariance(double v) {
    if (!(v > 0.0)) return 0.f;
    return v < 3.0e38 ? static_cast<float>(v) : 3.0e38f;
}

void checkInputs(const GuideBuffers& g, std::span<const vec3> color, std::span<const float> variance,
                 std::span<vec3> colorOut, std::span<float> varianceOut) {
    const std::size_t n = g.pixelCount();
    detail::checkSize(color.size(), n, "atrous: color");
    detail::checkSize(variance.size(), n, "atrous: variance");
    detail::checkSize(colorOut.size(), n, "atrous: colorOut");
    detail::checkSize(varianceOut.size(), n, "atrous: varianceOut");
}

// One iteration. `color` must be sanitised (finite, |c| <= kMaxRadiance);
// `lum` is scratch of the image size.
void iterate(const GuideBuffers& g, const std::vector<vec2>& grad, std::span<const vec3> color,
             std::span<const float> variance, int step, const AtrousParams& p, std::vector<float>& lum,
             std::span<vec3> colorOut, std::span<float> varianceOut) {
    const int w = g.width, h = g.height;
    const detail::NormalWeight normalWeight(p.sigmaN);
    lum.resize(color.size());
    detail::forEachIndex(color.size(), [&](std::size_t i) { lum[i] = luminance(color[i]); });
    detail::forEachPixel(w, h, [&](int x, int y, std::size_t i) {
        const vec3 c = color[i];
        const float varC = variance[i] > 0.f ? variance[i] : 0.f;
        if (g.isSky(i)) {
            colorOut[i] = c;
            varianceOut[i] = toFloatVariance(varC);
            return;
        }
        // 3x3 Gaussian of the variance around the centre (same sky state only).
        double gSum = 0.0, gW = 0.0;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const int px = x + dx, py = y + dy;
                if (px < 0 || py < 0 || px >= w || py >= h) continue;
                const std::size_t j = static_cast<std::size_t>(py) * static_cast<std::size_t>(w) + px;
                if (g.isSky(j)) continue;
                const double k = (dx == 0 ? 0.5 : 0.25) * (dy == 0 ? 0.5 : 0.25);
                const float v = variance[j];
                gSum += k * (v > 0.f ? static_cast<double>(v) : 0.0);
                gW += k;
            }
        const double blurredVar = gW > 0.0 ? gSum / gW : 0.0;
        const float lumDen = p.sigmaL * static_cast<float>(std::sqrt(blurredVar)) + p.luminanceEpsilon;
        const float invLumDen = lumDen > 0.f ? 1.f / lumDen : kInfinity;

        const float z = g.depth[i];
        const vec3 nrm = g.normal[i];
        const vec2 gz = grad[i];
        const float lc = lum[i];
        const double hc = static_cast<double>(kKernel[0]) * kKernel[0];
        double sumW = hc;  // centre: edge-stopping weight 1
        double sumW2Var = hc * hc * static_cast<double>(varC);
        double sr = hc * c.r, sg = hc * c.g, sb = hc * c.b;
        for (int ky = -2; ky <= 2; ++ky) {
            const int py = y + ky * step;
            if (py < 0 || py >= h) continue;
            const std::size_t row = static_cast<std::size_t>(py) * static_cast<std::size_t>(w);
            for (int kx = -2; kx <= 2; ++kx) {
                const int px = x + kx * step;
                if (px < 0 || px >= w || (kx == 0 && ky == 0)) continue;
                const std::size_t j = row + static_cast<std::size_t>(px);
                if (g.isSky(j)) continue;
                const float wn = normalWeight(nrm, g.normal[j]);
                if (!(wn > 0.f)) continue;
                const float termZ = detail::depthTerm(
                    z, g.depth[j], gz, vec2(static_cast<float>(kx * step), static_cast<float>(ky * step)), p.sigmaZ,
                    p.depthEpsilon);
                const float dl = std::fabs(lc - lum[j]);
                const float termL = dl != 0.f ? dl * invLumDen : 0.f;
                const float wgt = detail::expNeg(termZ + termL) * wn;
                if (!(wgt > 0.f)) continue;
                const double hw = static_cast<double>(kKernel[std::abs(kx)]) * kKernel[std::abs(ky)] * wgt;
                const vec3 cq = color[j];
                const float vq = variance[j];
                sumW += hw;
                sumW2Var += hw * hw * (vq > 0.f ? static_cast<double>(vq) : 0.0);
                sr += hw * cq.r;
                sg += hw * cq.g;
                sb += hw * cq.b;
            }
        }
        colorOut[i] = vec3(static_cast<float>(sr / sumW), static_cast<float>(sg / sumW), static_cast<float>(sb / sumW));
        varianceOut[i] = toFloatVariance(sumW2Var / (sumW * sumW));
    });
}

std::vector<vec3> sanitizedCopy(std::span<const vec3> color) {
    std::vector<vec3> out(color.size());
    detail::forEachIndex(color.size(), [&](std::size_t i) { out[i] = sanitize(color[i]); });
    return out;
}

}  // namespace

void atrousIteration(const GuideBuffers& g, std::span<const vec3> color, std::span<const float> variance, int step,
                     const AtrousParams& params, std::span<vec3> colorOut, std::span<float> varianceOut) {
    std::vector<vec2> scratch;
    const std::vector<vec2>& grad = detail::gradientOf(g, scratch);
    checkInputs(g, color, variance, colorOut, varianceOut);
    const std::vector<vec3> input = sanitizedCopy(color);
    std::vector<float> lum;
    iterate(g, grad, input, variance, std::clamp(step, 1, 1 << 20), params, lum, colorOut, varianceOut);
}

void atrousFilter(const GuideBuffers& g, std::span<const vec3> color, std::span<const float> variance,
                  const AtrousParams& params, std::span<vec3> colorOut, std::span<float> varianceOut,
                  int tapIterations, std::span<vec3> tapColor) {
    std::vector<vec2> scratch;
    const std::vector<vec2>& grad = detail::gradientOf(g, scratch);
    checkInputs(g, color, variance, colorOut, varianceOut);
    const std::size_t n = g.pixelCount();
    if (!tapColor.empty()) detail::checkSize(tapColor.size(), n, "atrous: tapColor");
    const int iterations = params.iterations > 0 ? params.iterations : 0;
    const int tap = std::clamp(tapIterations, 0, iterations);

    std::vector<vec3> c0 = sanitizedCopy(color), c1(n);
    std::vector<float> v0(variance.begin(), variance.end()), v1(n), lum;
    if (!tapColor.empty() && tap == 0) std::copy(color.begin(), color.end(), tapColor.begin());
    for (int it = 0; it < iterations; ++it) {
        iterate(g, grad, c0, v0, 1 << std::min(it, 20), params, lum, c1, v1);
        std::swap(c0, c1);
        std::swap(v0, v1);
        if (!tapColor.empty() && it + 1 == tap) std::copy(c0.begin(), c0.end(), tapColor.begin());
    }
    if (iterations == 0) {  // documented: plain copies
        std::copy(color.begin(), color.end(), colorOut.begin());
        std::copy(variance.begin(), variance.end(), varianceOut.begin());
        return;
    }
    std::copy(c0.begin(), c0.end(), colorOut.begin());
    std::copy(v0.begin(), v0.end(), varianceOut.begin());
}

}  // namespace rtlab::denoise
