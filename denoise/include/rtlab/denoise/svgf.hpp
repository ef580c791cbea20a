#pragma once
// Spatiotemporal Variance-Guided Filtering (Schied et al. 2017, HPG,
// "Spatiotemporal Variance-Guided Filtering: Real-Time Reconstruction for
// Path-Traced Global Illumination"), assembled from the shared stages:
//
//   [firefly clamp] -> reproject -> [history clamp] -> temporal accumulation
//   -> variance (temporal, or spatial 7x7 while history < 4)
//   -> a-trous x iterations (colour history taken after `historyTap` of them)
//
// Parameters follow the paper; where Falcor's SVGFPass defaults differ, the
// comment says so and SvgfParams::falcor() gives Falcor's set.
#include <rtlab/denoise/atrous.hpp>
#include <rtlab/denoise/clamp.hpp>
#include <rtlab/denoise/guides.hpp>
#include <rtlab/denoise/reprojection.hpp>
#include <rtlab/denoise/temporal.hpp>
#include <rtlab/denoise/variance.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace rtlab::denoise {

struct SvgfParams {
    ReprojectionParams reprojection;  // depth 10 / eps 1e-2 (Falcor), normal dot 0.9 (rtlab)
    TemporalParams temporal;          // alpha 0.2 (paper; Falcor 0.05), moments 0.2 (both), cap 32 (Falcor)
    VarianceParams variance;          // spatial 7x7 while history < 4 (paper and Falcor)
    AtrousParams atrous;              // 5 iterations (paper; Falcor 4), sigma z/n/l 1/128/4 (paper; Falcor l 10)
    // The colour history fed back to the next frame is the output after this
    // many a-trous iterations (0 = unfiltered accumulation). Source: paper (1,
    // "the first wavelet iteration"); Falcor's FeedbackTap = 1 counts from 0,
    // i.e. 2 here.
    int historyTap = 1;
    // Guide the a-trous passes by the variance of the accumulated colour (the
    // samples' luminance variance / n_eff, n_eff = min(history, (2 - alpha) /
    // alpha)) instead of the samples' variance: the luminance edge-stopping
    // tightens and the filter's reach shrinks as history builds up, so a static
    // view keeps converging instead of settling at the spatial filter's bias.
    // Source: rtlab (off: the paper and Falcor use the samples' variance).
    bool varianceOfMean = false;
    // Static pixels keep converging. Where the reprojection is exact (the
    // pixel's history comes from the same pixel, one tap of weight 1: a static
    // camera over static geometry) a second, unclamped accumulation runs with
    // alpha = 1/n and no cap on n, and feeds the a-trous passes instead of the
    // alpha-floored one; their luminance edge-stopping uses the variance of
    // that mean (the samples' variance / n), so the spatial filter's weights
    // collapse toward the pixel itself as n grows and the output tends to the
    // converged accumulation. A change of the signal on a static pixel (a
    // moving occluder's shadow, a light switched on) is caught by comparing
    // the long mean's luminance with the short-memory luminance moment
    // (alpha-floored, unclamped): beyond staticResetSigma standard deviations
    // of their difference (the samples' variance, 3x3-averaged, times 1/n_m +
    // 1/n) the long mean restarts from the alpha-floored accumulation. Pixels
    // whose reprojection is not exact (moving views) are filtered exactly as
    // without this. Source: rtlab (the anti-lag test follows the idea of
    // NVIDIA's ReLAX: a fast history guards a slow one).
    bool convergeStatic = false;
    float staticResetSigma = 4.f;
    // The change test takes the larger of the 3x3-averaged variance and the
    // variance of the long mean's own samples (since its last restart): a
    // bright, sparse signal among dim neighbours (a glossy floor seeing a
    // light's image in a mirror) has far more variance than their average,
    // and a run of its zero samples would otherwise restart it onto the
    // clamped fast history. Off by default: a firefly in a mean then widens
    // the test until the next restart (GI's 64-frame error on showcase 0.0038
    // -> 0.0082). Source: rtlab.
    bool staticResetOwnVariance = false;
    // The filtered output F of a static pixel is shrunk toward the long mean
    // M where their 3x3-averaged difference D (colour; its luminance d)
    // exceeds what the mean's noise explains: weight w = max(0, 1 - c V' / d^2)
    // with c = staticShrinkSigma2 (positive-part James-Stein for c = 1; larger
    // keeps more of the filter). The output moves by w (D + w_own R), R the
    // pixel's own rest (M - F) - D: w_own = max(0, 1 - c_own V_own / r^2)
    // with c_own = staticShrinkOwnSigma2, V_own the variance of this pixel's
    // mean (its own samples' or the 3x3 average's, the larger, / n), r R's
    // luminance; c_own = 0 takes R whole (the pixel moves by w (M - F)). A
    // positive c_own keeps heavy-tailed 1-spp signals (GI) from speckle: one
    // pixel's mean of 8-16 such samples is mostly noise, and taking it whole
    // wherever the neighbourhood showed a bias put that noise in the output
    // (showcase GI after 8-12 frames). Pixels whose long mean has fewer than
    // 8 samples are neither shrunk nor counted in the 3x3 average (so few
    // samples' variance misleads). Source: rtlab.
    float staticShrinkSigma2 = 1.f;
    float staticShrinkOwnSigma2 = 0.f;
    // The a-trous reach of a static pixel falls as its long mean grows: from
    // the full 2^iterations pixels while n <= 8 to 2^iterations (8 / n)^p,
    // p this (an iteration of step s runs where 2 s <= the reach; a stack's
    // own footprint still bounds it). The mean's noise falls with n, so the
    // spatial filter's bias, not its variance, comes to dominate; a shorter
    // reach trades the one for the other. 0: the full reach at every n.
    // Source: rtlab.
    float staticReachExponent = 0.f;
    // Firefly clamp of the noisy input. Source: rtlab (off; not in the paper).
    bool clampFireflies = false;
    FireflyClampParams firefly;
    // Clamp of the reprojected colour history. Source: paper (none).
    HistoryClampParams historyClamp;

    // The paper's set (= the defaults).
    static SvgfParams paper() { return {}; }
    // Falcor SVGFPass's default values: Iterations 4, FeedbackTap 1
    // (historyTap 2), PhiColor 10, PhiNormal 128, Alpha 0.05, MomentsAlpha 0.2,
    // and its 4/h boost of the spatial variance estimate. Values only: the
    // formulas stay the paper's (Falcor's depth weight uses fwidth(z) * step *
    // |offset|, its short-history pass also filters the colour, and it falls
    // back to a 3x3 bilateral search when all four reprojection taps fail).
    static SvgfParams falcor() {
        SvgfParams p;
        p.temporal.alpha = 0.05f;
        p.atrous.iterations = 4;
        p.atrous.sigmaL = 10.f;
        p.historyTap = 2;
        p.variance.boostShortHistory = true;
        return p;
    }
};

// SVGF with its history buffers held across frames. Deterministic: the output
// of a frame depends only on the frames since the last reset, never on the
// thread count.
class SvgfFilter {
public:
    explicit SvgfFilter(const SvgfParams& params = {}) : params_(params) {}

    const SvgfParams& params() const { return params_; }
    // New parameters apply from the next frame; the history is kept.
    void setParams(const SvgfParams& params) { params_ = params; }

    // Forgets all history: the next frame starts every pixel at history 1.
    void reset();

    // Filters one frame of (typically demodulated) noisy colour, guided by
    // `current`, into `out` (sizes must match the guides, else
    // std::invalid_argument; `out` may alias `noisyColor`). A change of image
    // size resets the history.
    // `footprintPx` (optional): per-pixel reach of the a-trous passes
    // (atrousFilter), for the per-effect stacks; empty = plain SVGF.
    void filter(const GuideBuffers& current, std::span<const vec3> noisyColor, std::span<vec3> out,
                std::span<const float> footprintPx = {});

    // Inspection of the last filtered frame (empty before the first).
    std::span<const float> historyLength() const { return history_.length; }
    std::span<const vec2> moments() const { return history_.moments; }
    // The variance estimate that guided the filter (before the a-trous passes).
    std::span<const float> variance() const { return variance_; }
    // The variance after the last a-trous iteration.
    std::span<const float> filteredVariance() const { return filteredVariance_; }
    // convergeStatic: the length of the static (alpha = 1/n) accumulation per
    // pixel (0 where the reprojection was not exact), and how many pixels the
    // change test restarted in the last frame.
    std::span<const float> staticLength() const { return staticLength_; }
    std::size_t staticResets() const { return staticResets_; }
    // 1 where the last frame found history by reprojection.
    std::span<const std::uint8_t> reprojectionValid() const { return valid_; }

private:
    // convergeStatic's long accumulation and change test (after the variance estimate).
    void convergeStatic(int width, int height);
    // convergeStatic's last step: the filtered output shrunk toward the long mean.
    void shrinkTowardStaticMean(int width, int height, std::span<vec3> out);

    SvgfParams params_;
    bool hasHistory_ = false;
    GuideBuffers prevGuides_;
    GuideBuffers curGuides_;
    HistoryBuffers history_;      // colour = feedback tap, moments, length
    HistoryBuffers reprojected_;  // scratch
    std::vector<vec3> input_;
    std::vector<vec3> tapColor_;
    std::vector<float> variance_;
    std::vector<float> filteredVariance_;
    std::vector<std::uint8_t> valid_;
    std::vector<std::uint8_t> static_;  // 1 where the reprojection is exact
    std::vector<vec3> staticColor_;     // the alpha = 1/n accumulation (convergeStatic)
    std::vector<vec2> staticMoments_;   // its luminance moments
    std::vector<float> staticLength_;
    std::vector<float> blurredVariance_;
    std::vector<vec4> shrinkTerms_;  // per static pixel: M - F, the variance of M
    std::vector<vec3> shrunk_;
    std::vector<float> staticReach_;
    std::size_t staticResets_ = 0;
    AtrousWorkspace atrousWorkspace_;
};

}  // namespace rtlab::denoise
