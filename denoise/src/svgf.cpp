#include <rtlab/denoise/svgf.hpp>

#include "detail.hpp"

#include <algorithm>
#include <utility>

namespace rtlab::denoise {

void SvgfFilter::reset() {
    hasHistory_ = false;
    frames_ = 0;
    history_ = HistoryBuffers{};
    prevGuides_ = GuideBuffers{};
    variance_.clear();
    filteredVariance_.clear();
    valid_.clear();
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
    } else {
        reprojected_.resize(w, h);
        valid_.assign(n, 0);
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
    if (params_.varianceOfMean) {
        // The accumulated colour is a mean of about n_eff samples: its variance is
        // the samples' variance / n_eff, n_eff = min(history, (2 - alpha) / alpha)
        // (an exponential moving average with weight alpha averages (2 - alpha) / alpha
        // samples in steady state).
        const float alpha = std::clamp(params_.temporal.alpha, 1e-3f, 1.f);
        const float steady = (2.f - alpha) / alpha;
        detail::forEachIndex(n, [&](std::size_t i) {
            const float nEff = std::clamp(reprojected_.length[i], 1.f, steady);
            variance_[i] /= nEff;
        });
    }
    filteredVariance_.resize(n);
    tapColor_.resize(n);
    atrousFilter(curGuides_, reprojected_.color, variance_, params_.atrous, out, filteredVariance_,
                 params_.historyTap, tapColor_, footprintPx, &atrousWorkspace_);

    // The next frame's history: the feedback-tap colour, the accumulated moments and lengths.
    std::swap(history_, reprojected_);
    std::swap(history_.color, tapColor_);
    std::swap(prevGuides_, curGuides_);
    hasHistory_ = true;
    ++frames_;
}

}  // namespace rtlab::denoise
