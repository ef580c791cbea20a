#include <rtlab/denoise/svgf.hpp>

#include "detail.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace rtlab::denoise {

namespace {
// Motion (pixels) below which a pixel counts as static for SvgfParams::convergeStatic.
constexpr float kStaticMotionPx = 1e-3f;
// Samples a static pixel's long mean needs before it is shrunk toward or
// counted as a neighbour (shrinkTowardStaticMean), and beyond which its
// a-trous reach starts to fall (staticReachExponent).
constexpr float kStaticMinSamples = 8.f;
// The variance of samples from their first two moments (0 where round-off makes it negative).
float momentsVariance(const vec2& m) {
    const float v = m.y - m.x * m.x;
    return v > 0.f ? v : 0.f;
}
}  // namespace

void SvgfFilter::reset() {
    hasHistory_ = false;
    history_ = HistoryBuffers{};
    prevGuides_ = GuideBuffers{};
    variance_.clear();
    filteredVariance_.clear();
    valid_.clear();
    static_.clear();
    staticColor_.clear();
    staticMoments_.clear();
    staticLength_.clear();
    staticReach_.clear();
    staticResets_ = 0;
}

void SvgfFilter::filter(const GuideBuffers& current, std::span<const vec3> noisyColor, std::span<vec3> out,
                        std::span<const float> footprintPx) {
    current.validate();
    const std::size_t n = current.pixelCount();
    detail::checkSize(noisyColor.size(), n, "SvgfFilter::filter: noisyColor");
    detail::checkSize(out.size(), n, "SvgfFilter::filter: out");
    const int w = current.width, h = current.height;
    if (hasHistory_ && (prevGuides_.width != w || prevGuides_.height != h)) reset();

    curGuides_ = current;
    ensureDepthGradient(curGuides_);

    // Input: sanitised, optionally firefly-clamped (copied, so out may alias it).
    input_.resize(n);
    if (params_.clampFireflies) {
        clampFireflies(w, h, noisyColor, input_, params_.firefly);
    } else {
        detail::forEachIndex(n, [&](std::size_t i) { input_[i] = sanitize(noisyColor[i]); });
    }

    // Reprojection of the history.
    if (hasHistory_) {
        const Reprojection r = reproject(curGuides_, prevGuides_, params_.reprojection);
        reprojectHistory(r, history_, reprojected_);
        valid_ = r.valid;
        static_.resize(n);
        detail::forEachIndex(n, [&](std::size_t i) {
            // Exact: the pixel's own previous value carries (nearly) all of the
            // bilinear weight. A still camera's motion vectors are not exactly 0
            // (round-off of the projection: ~1e-5 px), hence the tolerance.
            const ReprojectionTaps& t = r.taps[i];
            bool own = false;
            for (int k = 0; k < 4; ++k) own = own || (t.index[k] == i && t.weight[k] >= 1.f - kStaticMotionPx);
            const vec2 m = curGuides_.motion[i];
            static_[i] = r.valid[i] && own && std::fabs(m.x) <= kStaticMotionPx && std::fabs(m.y) <= kStaticMotionPx;
        });
    } else {
        reprojected_.resize(w, h);
        valid_.assign(n, 0);
        static_.assign(n, 0);
    }
    // Pixels the footprint keeps sharp (0: no spatial filter, e.g. mirrors)
    // keep their history unclamped: the clamp's box comes from the noisy
    // neighbourhood, and pulling a sharp, converged history into it would
    // blur the detail the footprint protects. Their noise is averaged by the
    // temporal accumulation alone.
    std::vector<std::pair<std::size_t, vec3>> sharp;
    if (params_.historyClamp.mode != HistoryClampMode::None && !footprintPx.empty())
        for (std::size_t i = 0; i < n; ++i)
            if (!(footprintPx[i] > 0.f) && !curGuides_.isSky(i)) sharp.emplace_back(i, reprojected_.color[i]);
    clampHistory(w, h, input_, reprojected_.color, reprojected_.length, params_.historyClamp);
    for (const auto& [i, c] : sharp) reprojected_.color[i] = c;

    // Temporal accumulation (in place in reprojected_), variance, a-trous.
    accumulateTemporal(input_, reprojected_, params_.temporal, reprojected_);
    variance_.resize(n);
    estimateVariance(curGuides_, reprojected_, params_.variance, variance_);
    if (params_.convergeStatic) {
        convergeStatic(w, h);
    } else {
        staticLength_.clear();
        staticResets_ = 0;
    }
    if (params_.varianceOfMean) {
        // The accumulated colour is a mean of about n_eff samples: its variance is
        // the samples' variance / n_eff, n_eff = min(history, (2 - alpha) / alpha)
        // (an exponential moving average with weight alpha averages (2 - alpha) / alpha
        // samples in steady state).
        const float alpha = std::clamp(params_.temporal.alpha, 1e-3f, 1.f);
        const float steady = (2.f - alpha) / alpha;
        detail::forEachIndex(n, [&](std::size_t i) {
            if (params_.convergeStatic && static_[i]) return;  // divided by the static length already
            const float nEff = std::clamp(reprojected_.length[i], 1.f, steady);
            variance_[i] /= nEff;
        });
    }
    // Static pixels' reach: (8 / n)^p of the full one once the long mean has more than 8 samples.
    // (Until some pixel has that many, the footprint as given: a full reach
    // everywhere would filter the same, on the a-trous passes' slower
    // per-pixel path.)
    std::span<const float> reach = footprintPx;
    const bool anyLongMean =
        params_.convergeStatic && params_.staticReachExponent > 0.f &&
        std::any_of(staticLength_.begin(), staticLength_.end(), [](float len) { return len > kStaticMinSamples; });
    if (anyLongMean) {
        const float full = std::ldexp(1.f, std::clamp(params_.atrous.iterations, 0, 30));
        staticReach_.resize(n);
        detail::forEachIndex(n, [&](std::size_t i) {
            float r = footprintPx.empty() ? full : footprintPx[i];
            if (static_[i] && staticLength_[i] > kStaticMinSamples)
                r = std::min(r, full * std::pow(kStaticMinSamples / staticLength_[i], params_.staticReachExponent));
            staticReach_[i] = r;
        });
        reach = staticReach_;
    }
    filteredVariance_.resize(n);
    tapColor_.resize(n);
    atrousFilter(curGuides_, reprojected_.color, variance_, params_.atrous, out, filteredVariance_, params_.historyTap,
                 tapColor_, reach, &atrousWorkspace_);
    if (params_.convergeStatic) shrinkTowardStaticMean(w, h, out);

    // The next frame's history: the feedback-tap colour, the accumulated moments and lengths.
    std::swap(history_, reprojected_);
    std::swap(history_.color, tapColor_);
    std::swap(prevGuides_, curGuides_);
    hasHistory_ = true;
}

void SvgfFilter::shrinkTowardStaticMean(int w, int h, std::span<vec3> out) {
    // Static pixels: the filtered value F and the long mean M estimate the
    // same signal; F has little variance and some bias, M no bias and the
    // variance of the mean V = Var / n. Two positive-part James-Stein steps:
    //  1. the bias: D = M - F averaged over the 3x3 static neighbourhood (a
    //     bias is spatially coherent, M's noise is not), V' its variance (the
    //     neighbours' V summed / count^2), weight w = max(0, 1 - c V' / d^2)
    //     on D's luminance d (c = staticShrinkSigma2 > 1: more conservative);
    //  2. the pixel's own rest R = (M - F) - D, weight
    //     w_own = max(0, 1 - c_own V / r^2) on R's luminance r, V this
    //     pixel's mean variance (its own samples' or the 3x3 average's, the
    //     larger, / n; c_own = staticShrinkOwnSigma2; 0 takes R whole).
    // The output is F + w (D + w_own R). As n grows V -> 0, both weights -> 1
    // and the output tends to M, the converged accumulation.
    const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    // The variance of the long mean, from its own samples' moments (every
    // sample since the last restart: a firefly among them raises it, so that
    // pixel keeps F). Below kStaticMinSamples samples no pixel is shrunk or counted:
    // so few samples' variance is no guide for heavy-tailed 1-spp signals. A
    // run of 1-spp GI samples of 0 shows none and pulled pixels onto their
    // few-sample mean (dark speckle); one firefly among three samples sits
    // 1.2 sigma from F in the 3x3 mean and pulled its pixel a third of the way
    // up (bright speckle; both in make demo's frame_0001 and frame_0002).
    const auto counted = [&](std::size_t j) { return static_[j] && staticLength_[j] >= kStaticMinSamples; };
    // No pixel with a long enough mean (a first frame, a moving view): nothing moves.
    bool anyCounted = false;
    for (std::size_t i = 0; i < n && !anyCounted; ++i) anyCounted = counted(i);
    if (!anyCounted) return;
    const float c = params_.staticShrinkSigma2, cOwn = params_.staticShrinkOwnSigma2;
    // Per counted pixel once: M - F and the variance of its mean.
    shrinkTerms_.resize(n);
    detail::forEachIndex(n, [&](std::size_t i) {
        shrinkTerms_[i] =
            counted(i) ? vec4(reprojected_.color[i] - out[i], momentsVariance(staticMoments_[i]) / staticLength_[i])
                       : vec4(0.f);
    });
    shrunk_.resize(n);
    detail::forEachPixel(w, h, [&](int x, int y, std::size_t i) {
        shrunk_[i] = out[i];
        if (!counted(i)) return;
        vec3 sumD(0.f);
        float sumV = 0.f;
        int count = 0;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const int px = x + dx, py = y + dy;
                if (px < 0 || py < 0 || px >= w || py >= h) continue;
                const std::size_t j = static_cast<std::size_t>(py) * static_cast<std::size_t>(w) + px;
                if (!counted(j)) continue;
                sumD += vec3(shrinkTerms_[j]);
                sumV += shrinkTerms_[j].w;
                ++count;
            }
        // Step 1: the neighbourhood's coherent difference.
        const vec3 d = sumD / static_cast<float>(count);
        const float dL = luminance(d), v = c * sumV / static_cast<float>(count * count);
        if (!(dL * dL > v)) return;
        const float wgt = 1.f - v / (dL * dL);
        // Step 2: the pixel's own rest, by its own mean's variance (c_own = 0:
        // the whole M - F, the one-step rule).
        const vec3 diff(shrinkTerms_[i]);
        if (!(cOwn > 0.f)) {
            shrunk_[i] = out[i] + wgt * diff;
            return;
        }
        const vec3 rest = diff - d;
        const float rL = luminance(rest);
        const float own = cOwn * std::max(shrinkTerms_[i].w, blurredVariance_[i] / staticLength_[i]);
        // A mean without variance (own = 0) is taken whole, as c_own = 0 would.
        const float restWgt = !(own > 0.f) ? 1.f : rL * rL > own ? 1.f - own / (rL * rL) : 0.f;
        shrunk_[i] = out[i] + wgt * (d + restWgt * rest);
    });
    std::copy(shrunk_.begin(), shrunk_.end(), out.begin());
}

void SvgfFilter::convergeStatic(int w, int h) {
    const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    if (staticColor_.size() != n) {
        staticColor_.assign(n, vec3(0.f));
        staticMoments_.assign(n, vec2(0.f));
        staticLength_.assign(n, 0.f);
    }
    // The samples' luminance variance averaged over the 3x3 neighbourhood: a
    // pixel's own moments can show no variance (a run of equal 1-spp samples).
    // Only static pixels read it (none in a first frame or a moving view).
    blurredVariance_.resize(n);
    if (std::any_of(static_.begin(), static_.end(), [](std::uint8_t s) { return s != 0; })) {
        detail::forEachPixel(w, h, [&](int x, int y, std::size_t i) {
            float sum = 0.f;
            int count = 0;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int px = x + dx, py = y + dy;
                    if (px < 0 || py < 0 || px >= w || py >= h) continue;
                    sum += variance_[static_cast<std::size_t>(py) * static_cast<std::size_t>(w) + px];
                    ++count;
                }
            blurredVariance_[i] = sum / static_cast<float>(count);
        });
    }
    const float alpha = std::clamp(params_.temporal.alpha, 1e-3f, 1.f);
    const float momentsAlpha = std::clamp(params_.temporal.momentsAlpha, 1e-3f, 1.f);
    const float steady = (2.f - alpha) / alpha, steadyMoments = (2.f - momentsAlpha) / momentsAlpha;
    const float k = params_.staticResetSigma;
    std::vector<std::uint8_t> reset(n, 0);
    detail::forEachIndex(n, [&](std::size_t i) {
        const vec3 fast = reprojected_.color[i];
        const float fastN = std::clamp(reprojected_.length[i], 1.f, steady);
        if (!static_[i] || !(staticLength_[i] > 0.f)) {
            // Not static (or no static history yet): start from the alpha-floored accumulation.
            staticColor_[i] = fast;
            staticMoments_[i] = reprojected_.moments[i];
            staticLength_[i] = static_[i] ? fastN : 0.f;
            if (static_[i]) variance_[i] /= fastN;
            return;
        }
        const float len = staticLength_[i] + 1.f;
        const vec3 sample = input_[i];
        const vec3 mean = staticColor_[i] + (sample - staticColor_[i]) / len;
        // The change test: the long mean against the short-memory luminance moment.
        const float nm = std::clamp(reprojected_.length[i], 1.f, steadyMoments);
        const float d = std::fabs(luminance(mean) - reprojected_.moments[i].x);
        // The samples' variance: the 3x3 average, or (staticResetOwnVariance)
        // the long mean's own samples' where larger.
        const float variance = params_.staticResetOwnVariance
                                   ? std::max(momentsVariance(staticMoments_[i]), blurredVariance_[i])
                                   : blurredVariance_[i];
        const float tolerance = k * std::sqrt(variance * (1.f / nm + 1.f / len));
        if (d > tolerance && d > 1e-6f * std::fabs(reprojected_.moments[i].x)) {
            staticColor_[i] = fast;
            staticMoments_[i] = reprojected_.moments[i];
            staticLength_[i] = fastN;
            reset[i] = 1;
        } else {
            staticColor_[i] = mean;
            staticMoments_[i] += (luminanceMoments(sample) - staticMoments_[i]) / len;
            staticLength_[i] = len;
        }
        // The a-trous passes filter the long mean, guided by its variance.
        reprojected_.color[i] = staticColor_[i];
        variance_[i] /= staticLength_[i];
    });
    staticResets_ = 0;
    for (std::uint8_t r : reset) staticResets_ += r;
}

}  // namespace rtlab::denoise
