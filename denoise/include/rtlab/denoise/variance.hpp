#pragma once
// Per-pixel luminance variance from the temporally accumulated moments, with
// a spatial fallback while the history is short (SVGF, Schied et al. 2017,
// section 4.2).
#include <rtlab/denoise/guides.hpp>
#include <rtlab/denoise/temporal.hpp>

#include <span>

namespace rtlab::denoise {

struct VarianceParams {
    // Below this history length (frames) the variance is estimated spatially.
    // Source: paper and Falcor (4).
    float historyThreshold = 4.f;
    // Half-width of the spatial window: 3 = 7x7 (at most 3). Source: paper and Falcor.
    int radius = 3;
    // Bilateral weights of the spatial estimate, driven by depth and normal
    // only (paper): exp(-|z - z'| / (sigmaZ |grad z . offset| + depthEpsilon * z))
    // * max(0, n.n')^sigmaN. sigmaZ / sigmaN: paper's a-trous values (1, 128).
    // Falcor also uses a luminance weight here and a 3x wider depth tolerance.
    float sigmaZ = 1.f;
    float sigmaN = 128.f;
    // Relative depth epsilon (the paper's "small epsilon"; rtlab scales it with
    // the centre depth so that it is unit-free). Source: rtlab.
    float depthEpsilon = 1e-3f;
    // Falcor multiplies the spatial estimate by 4 / history ("boost for the
    // first frames"; here historyThreshold / history); the paper does not.
    // Source of the default: paper.
    bool boostShortHistory = false;
};

// variance[i] = max(0, E[l^2] - E[l]^2) of the pixel's accumulated moments when
// accumulated.length[i] >= historyThreshold (and on sky pixels); otherwise the
// same from the bilateral-weighted mean of the moments over the window (sky
// neighbours excluded). Never negative, NaN or Inf for finite moments.
void estimateVariance(const GuideBuffers& guides, const HistoryBuffers& accumulated, const VarianceParams& params,
                      std::span<float> variance);

}  // namespace rtlab::denoise
