#include <rtlab/denoise/footprint.hpp>

#include "detail.hpp"

#include <algorithm>
#include <cmath>

namespace rtlab::denoise {
namespace {

void checkSizes(int width, int height, std::initializer_list<std::size_t> sizes) {
    const std::size_t n = detail::pixelCount(width, height);
    for (const std::size_t s : sizes) detail::checkSize(s, n, "footprint: buffer");
}

// worldSize / pixelWorld in pixels, 0 for non-positive or non-finite input, capped.
float toPixels(float worldSize, float pixelWorld, float maxPx) {
    if (!(worldSize > 0.f) || !(pixelWorld > 0.f)) return 0.f;
    const float px = worldSize / pixelWorld;
    return px < maxPx ? px : maxPx;  // +inf and NaN-free: worldSize, pixelWorld > 0
}

// Mean over the (2r+1)^2 window of geometry pixels (same-state only), then
// [minPx, maxPx] where > 0. With `estimate` (one flag per pixel), only the
// flagged geometry pixels of the window count, and a window without any
// falls back to all its geometry pixels. Separable: row sums of values and
// of counts, then column sums of those (the same window, in O(r) per pixel).
std::vector<float> smoothAndClamp(int w, int h, const std::vector<float>& px, std::span<const int> meshId,
                                  const FootprintParams& p, std::span<const std::uint8_t> estimate = {}) {
    const std::size_t n = px.size();
    std::vector<float> out(n, 0.f);
    std::vector<vec4> rowSums(n);  // sum, count over geometry; sum, count over estimates
    const int r = std::max(p.smoothRadius, 0);
    const float lo = std::min(p.minPx, p.maxPx), hi = std::max(p.minPx, p.maxPx);
    detail::forEachPixel(w, h, [&](int x, int y, std::size_t i) {
        const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        vec4 s(0.f);
        for (int qx = std::max(0, x - r); qx <= std::min(w - 1, x + r); ++qx) {
            if (meshId[row + qx] < 0) continue;
            s += vec4(px[row + qx], 1.f, 0.f, 0.f);
            if (!estimate.empty() && estimate[row + qx]) s += vec4(0.f, 0.f, px[row + qx], 1.f);
        }
        rowSums[i] = s;
    });
    detail::forEachPixel(w, h, [&](int x, int y, std::size_t i) {
        if (meshId[i] < 0) return;
        vec4 s(0.f);
        for (int qy = std::max(0, y - r); qy <= std::min(h - 1, y + r); ++qy)
            s += rowSums[static_cast<std::size_t>(qy) * static_cast<std::size_t>(w) + x];
        const float m = s.w > 0.f ? s.z / s.w : (s.y > 0.f ? s.x / s.y : 0.f);
        out[i] = std::max(m > 0.f ? std::clamp(m, lo, hi) : 0.f, std::min(p.floorPx, hi));
    });
    return out;
}

}  // namespace

std::vector<float> surfacePixelWorld(std::span<const float> pixelWorld, std::span<const vec2> depthGrad) {
    detail::checkSize(depthGrad.size(), pixelWorld.size(), "footprint: depth gradient");
    // sqrt(1 / cos theta) = (1 + tan^2 theta)^(1/4), tan^2 theta capped at 1e8 (a factor of 100).
    constexpr float kMaxTan2 = 1e8f;
    std::vector<float> out(pixelWorld.size());
    detail::forEachIndex(out.size(), [&](std::size_t i) {
        const float pw = pixelWorld[i];
        if (!(pw > 0.f) || !std::isfinite(pw)) {
            out[i] = pw;
            return;
        }
        const vec2 g = depthGrad[i];
        const float slope2 = (g.x * g.x + g.y * g.y) / (pw * pw);
        const float tan2 = slope2 < kMaxTan2 ? slope2 : (std::isnan(slope2) ? 0.f : kMaxTan2);
        out[i] = pw * std::sqrt(std::sqrt(1.f + tan2));
    });
    return out;
}

std::vector<float> shadowFootprint(int width, int height, std::span<const float> penumbraWorld,
                                   std::span<const float> pixelWorld, std::span<const int> meshId,
                                   const FootprintParams& params, int searchRadius) {
    checkSizes(width, height, {penumbraWorld.size(), pixelWorld.size(), meshId.size()});
    const std::size_t n = penumbraWorld.size();
    // Step: the estimate where an occluder was seen.
    std::vector<float> px(n);
    detail::forEachIndex(n, [&](std::size_t i) {
        px[i] = meshId[i] < 0 ? 0.f : toPixels(penumbraWorld[i], pixelWorld[i], params.maxPx);
    });
    // Step: blocker search — separable max over the search window fills the gaps.
    const int r = std::max(searchRadius, 0);
    std::vector<float> rowMax(n), windowMax(n);
    detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
        float m = 0.f;
        const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(width);
        for (int qx = std::max(0, x - r); qx <= std::min(width - 1, x + r); ++qx) m = std::max(m, px[row + qx]);
        rowMax[i] = m;
    });
    detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
        float m = 0.f;
        for (int qy = std::max(0, y - r); qy <= std::min(height - 1, y + r); ++qy)
            m = std::max(m, rowMax[static_cast<std::size_t>(qy) * static_cast<std::size_t>(width) + x]);
        windowMax[i] = m;
    });
    detail::forEachIndex(n, [&](std::size_t i) {
        if (meshId[i] >= 0 && !(px[i] > 0.f)) px[i] = windowMax[i];
    });
    return smoothAndClamp(width, height, px, meshId, params);
}

std::vector<float> reflectionFootprint(int width, int height, std::span<const float> roughness,
                                       std::span<const float> hitT, std::span<const float> pixelWorld,
                                       std::span<const int> meshId, const FootprintParams& params, float lobeScale) {
    checkSizes(width, height, {roughness.size(), hitT.size(), pixelWorld.size(), meshId.size()});
    std::vector<float> px(roughness.size());
    detail::forEachIndex(px.size(), [&](std::size_t i) {
        if (meshId[i] < 0) {
            px[i] = 0.f;
            return;
        }
        const float r = detail::clampNaNLow(roughness[i], 0.f, 1.f);
        const float alpha = r * r;
        if (!(alpha > 0.f)) {
            px[i] = 0.f;
            return;
        }
        const float lobeWorld = hitT[i] > 0.f ? lobeScale * alpha * hitT[i] : kInfinity;
        px[i] = std::isinf(lobeWorld) ? params.maxPx : toPixels(lobeWorld, pixelWorld[i], params.maxPx);
    });
    std::vector<float> out = smoothAndClamp(width, height, px, meshId, params);
    // Edges of the reflected image: the window's hit distances (same mesh)
    // far apart. First the span over every geometry pixel of the window, by
    // separable min / max (a superset of the pixels to cap), then the
    // same-mesh span for those pixels only.
    if (params.edgeHitRatio > 0.f) {
        constexpr float kMissDistance = 1e4f;
        const int r = std::max(params.smoothRadius, 0);
        const float cap = std::max(params.edgeCapPx, 0.f);
        const auto distance = [&](std::size_t q) {
            return hitT[q] > 0.f ? std::min(hitT[q], kMissDistance) : kMissDistance;  // NaN: a miss
        };
        std::vector<vec2> rowSpan(out.size());  // (nearest, farthest) over the row's window
        detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
            const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(width);
            vec2 span(kMissDistance, 0.f);
            for (int qx = std::max(0, x - r); qx <= std::min(width - 1, x + r); ++qx) {
                const std::size_t q = row + static_cast<std::size_t>(qx);
                if (meshId[q] < 0) continue;
                const float t = distance(q);
                span = vec2(std::min(span.x, t), std::max(span.y, t));
            }
            rowSpan[i] = span;
        });
        // Each pixel reads only its own footprint: capped in place.
        detail::forEachPixel(width, height, [&](int x, int y, std::size_t i) {
            if (meshId[i] < 0 || !(out[i] > cap)) return;  // sky, or nothing to cap
            vec2 span(kMissDistance, 0.f);
            for (int qy = std::max(0, y - r); qy <= std::min(height - 1, y + r); ++qy) {
                const vec2 s = rowSpan[static_cast<std::size_t>(qy) * static_cast<std::size_t>(width) +
                                       static_cast<std::size_t>(x)];
                span = vec2(std::min(span.x, s.x), std::max(span.y, s.y));
            }
            if (!(span.y > params.edgeHitRatio * span.x)) return;
            float nearest = kMissDistance, farthest = 0.f;
            for (int qy = std::max(0, y - r); qy <= std::min(height - 1, y + r); ++qy) {
                const std::size_t row = static_cast<std::size_t>(qy) * static_cast<std::size_t>(width);
                for (int qx = std::max(0, x - r); qx <= std::min(width - 1, x + r); ++qx) {
                    const std::size_t q = row + static_cast<std::size_t>(qx);
                    if (meshId[q] != meshId[i]) continue;
                    const float t = distance(q);
                    nearest = std::min(nearest, t), farthest = std::max(farthest, t);
                }
            }
            if (farthest > params.edgeHitRatio * nearest) out[i] = cap;
        });
    }
    // Near-mirrors: their own lobe, nothing from the neighbours or the floor.
    if (params.sharpBelowRoughness > 0.f)
        detail::forEachIndex(out.size(), [&](std::size_t i) {
            if (meshId[i] < 0) return;
            const float r = detail::clampNaNLow(roughness[i], 0.f, 1.f);
            if (!(r < params.sharpBelowRoughness)) return;
            const float own = hitT[i] > 0.f ? px[i] : 0.f;
            out[i] = own < params.minPx ? 0.f : std::min(own, params.maxPx);
        });
    return out;
}

std::vector<float> aoFootprint(int width, int height, std::span<const float> hitT, std::span<const float> visibility,
                               std::span<const float> pixelWorld, std::span<const int> meshId,
                               const FootprintParams& params) {
    checkSizes(width, height, {hitT.size(), visibility.size(), pixelWorld.size(), meshId.size()});
    std::vector<float> px(hitT.size());
    std::vector<std::uint8_t> occluded(hitT.size());
    detail::forEachIndex(px.size(), [&](std::size_t i) {
        px[i] = meshId[i] < 0 ? 0.f : toPixels(hitT[i], pixelWorld[i], params.maxPx);
        occluded[i] = visibility[i] < 1.f ? 1 : 0;  // NaN: no estimate
    });
    // Only the pixels that saw an occluder, where the window has any: one
    // unoccluded 1-spp sample in a contact crease must not widen its
    // neighbours' footprint to the AO radius.
    return smoothAndClamp(width, height, px, meshId, params, occluded);
}

}  // namespace rtlab::denoise
