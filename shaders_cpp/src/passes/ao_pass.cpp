// Ambient occlusion: cosine-hemisphere rays around the shading normal,
// limited to RenderSettings::aoRadius; visibility and the nearest occluder's
// distance (a closest-hit query, so the distance is the same on every back
// end; a first-hit query would report whichever occluder traversal met first).
// Contact sampling: after the spp samples of every pixel, the pixels near a
// contact (RenderSettings::aoContactExtraSamples) get more, traced as one
// compact list so that the rest of the image costs nothing.
#include "../lighting.hpp"
#include "passes.hpp"

#include <rtlab/core/parallel.hpp>
#include <stdexcept>

namespace rtlab::shaders::detail {

namespace {

// For every pixel, the sum of `in` over the other pixels of its
// (2 kAoContactWindow + 1)^2 window (clipped at the image's border): a row
// pass, then a column pass, in exact integers.
std::vector<std::uint16_t> windowSumsOfOthers(int width, int height, const std::vector<std::uint8_t>& in) {
    const std::size_t w = static_cast<std::size_t>(width);
    std::vector<std::uint16_t> rows(in.size()), out(in.size());
    parallelForEach(static_cast<std::size_t>(height), [&](std::size_t y) {
        const std::uint8_t* row = in.data() + y * w;
        for (int x = 0; x < width; ++x) {
            std::uint16_t sum = 0;
            for (int q = std::max(0, x - kAoContactWindow); q <= std::min(width - 1, x + kAoContactWindow); ++q)
                sum += row[q];
            rows[y * w + static_cast<std::size_t>(x)] = sum;
        }
    });
    parallelForEach(static_cast<std::size_t>(height), [&](std::size_t y) {
        const int yi = static_cast<int>(y);
        for (std::size_t x = 0; x < w; ++x) {
            std::uint16_t sum = 0;
            for (int q = std::max(0, yi - kAoContactWindow); q <= std::min(height - 1, yi + kAoContactWindow); ++q)
                sum += rows[static_cast<std::size_t>(q) * w + x];
            out[y * w + x] = static_cast<std::uint16_t>(sum - in[y * w + x]);
        }
    });
    return out;
}

}  // namespace

std::vector<std::uint32_t> aoContactSampleCounts(int width, int height, std::span<const float> occluderDistance,
                                                 std::span<const std::uint8_t> geometry, float nearDistance,
                                                 std::uint32_t perSample, std::size_t budgetPerPixel) {
    const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    if (occluderDistance.size() != n || geometry.size() != n)
        throw std::invalid_argument("aoContactSampleCounts: buffers do not match the image size");
    std::vector<std::uint32_t> counts(n, 0);
    if (perSample == 0) return counts;
    // Step: the sources (pixels that saw a near occluder) in each geometry
    // pixel's window, itself left out.
    std::vector<std::uint8_t> source(n);
    for (std::size_t i = 0; i < n; ++i) source[i] = occluderDistance[i] < nearDistance;
    std::vector<std::uint16_t> sources = windowSumsOfOthers(width, height, source);
    std::size_t geometryPixels = 0, flagged = 0;
    std::vector<std::uint8_t> flaggedOnce(n);  // flagged by exactly one source
    for (std::size_t i = 0; i < n; ++i) {
        if (!geometry[i]) sources[i] = 0;
        geometryPixels += geometry[i] != 0, flagged += sources[i] != 0;
        flaggedOnce[i] = sources[i] == 1;
    }
    // Step: per flagged pixel, the count the budget affords, from the number
    // of flagged pixels had its own samples seen no near occluder (those
    // whose only source it is are taken off), plus the most it can flag
    // (24): its own samples do not move its count, and the counts still sum
    // to at most budgetPerPixel x the geometry pixels.
    constexpr std::size_t kMostFlaggedByOne = (2 * kAoContactWindow + 1) * (2 * kAoContactWindow + 1) - 1;
    const std::vector<std::uint16_t> flaggedOnceAround = windowSumsOfOthers(width, height, flaggedOnce);
    parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            if (!sources[i]) continue;
            // A source pixel is the only source of the flagged-once pixels in its window.
            const std::size_t onlyThroughMe = source[i] ? flaggedOnceAround[i] : 0;
            const std::size_t others = flagged - onlyThroughMe + kMostFlaggedByOne;
            counts[i] =
                static_cast<std::uint32_t>(std::min<std::size_t>(perSample, budgetPerPixel * geometryPixels / others));
        }
    });
    return counts;
}

namespace {

// The flagged pixels are traced on a grid this wide (item = row x width +
// column): a 16x16 tile of the dispatch is 256 consecutive pixels of the list.
constexpr int kListGridWidth = 16;
// At most this many contact samples per geometry pixel and sample on
// average: where contacts are everywhere (slivers, a hairball, dense foliage) the
// per-pixel counts fall so that AO costs at most three times its uniform
// rays (showcase flags 21 % of the pixels at 96x54, 12 % at 320x180).
constexpr std::size_t kContactBudgetPerPixel = 2;

}  // namespace

std::uint64_t runAmbientOcclusionPass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    Image& out = passFrame.out.image;
    const std::size_t n = ctx.gbuffer.size();
    const int spp = ctx.settings.spp;
    const float radius = ctx.settings.aoRadius;
    float* visibility = out.addChannel("ao.V", 1.f);
    float* hitT = out.addChannel("ao.hitT", 0.f);
    VisibilityTally tally(n);
    std::uint64_t bytes = n * 2 * sizeof(float) + tally.bytes();
    // The spp uniform samples are stratified over the screen only without
    // contact sampling: a pixel's contact count follows its neighbours'
    // samples, which stratification correlates with its own, and a count
    // that depends on a pixel's own samples biases its mean
    // (aoContactSampleCounts). Contact samples (s >= spp) are independent.
    const bool stratified = ctx.settings.aoContactExtraSamples <= 0;
    // Sample s of pixel i: a cosine direction, or nullopt where nothing is traced.
    const auto aoRay = [&](std::size_t i, std::uint32_t s) -> std::optional<tracer::RayDesc> {
        const GPixel& g = ctx.gbuffer[i];
        if (!g.hit || !(radius > 0.f)) return std::nullopt;
        const SampleKey key = ctx.key(i, s, stream::kAmbientOcclusion);
        const vec2 u = stratified && s < static_cast<std::uint32_t>(spp)
                           ? ctx.screenStratified2D(i, s, stream::kAmbientOcclusion)
                           : vec2(sampleUniform(key, 0), sampleUniform(key, 1));
        const vec3 dir = cosineDirectionAbove(g.normal, g.geometricNormal, u);
        return tracer::RayDesc{rayOriginLeaving(g.position, g.geometricNormal, dir, g.errorScale), 0.f, dir, radius};
    };
    // Step: spp samples in every pixel.
    for (int s = 0; s < spp; ++s)
        counters.add(ctx.pipeline().dispatchCoherent(
            ctx.width, ctx.height, ctx.args(kRayOcclusion),
            [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
                const std::size_t i = ctx.pixelIndex(x, y);
                std::optional<tracer::RayDesc> ray = aoRay(i, static_cast<std::uint32_t>(s));
                if (ray) ++tally.tested[i];
                return ray;
            },
            [&](int x, int y, const HitPayload& p) { tally.record(ctx.pixelIndex(x, y), p); },
            tracer::RayCoherence::Incoherent));

    // Step: contact sampling. Samples spp .. spp + count - 1 of the pixels
    // near a contact (aoContactSampleCounts), one dispatch per extra sample
    // over the list of those pixels: a pixel appears once per dispatch, so
    // its tally grows in sample order (the same sums for any thread count).
    const int perSample = std::max(ctx.settings.aoContactExtraSamples, 0);
    if (perSample > 0 && radius > 0.f) {
        // The mean occluder distance each pixel saw (+inf: none) decides its neighbours' counts.
        std::vector<float> occluderDistance(n, kInfinity);
        std::vector<std::uint8_t> geometry(n, 0);
        for (std::size_t i = 0; i < n; ++i) {
            geometry[i] = ctx.gbuffer[i].hit;
            if (tally.occluded[i]) occluderDistance[i] = tally.meanOccluderDistance(i, kInfinity);
        }
        const std::vector<std::uint32_t> counts = aoContactSampleCounts(
            ctx.width, ctx.height, occluderDistance, geometry, std::max(ctx.settings.aoContactFraction, 0.f) * radius,
            static_cast<std::uint32_t>(perSample), kContactBudgetPerPixel);
        std::vector<std::uint32_t> pixels;  // the flagged pixels; a pixel's extra count is counts[i] x spp
        std::uint32_t most = 0;
        for (std::size_t i = 0; i < n; ++i)
            if (counts[i]) pixels.push_back(static_cast<std::uint32_t>(i)), most = std::max(most, counts[i]);
        bytes +=
            n * (sizeof(float) + sizeof(std::uint8_t) + sizeof(std::uint32_t)) + pixels.size() * sizeof(std::uint32_t);
        const int rows = static_cast<int>((pixels.size() + kListGridWidth - 1) / kListGridWidth);
        const auto pixelOf = [&](int x, int y) -> std::optional<std::size_t> {
            const std::size_t item = static_cast<std::size_t>(y) * kListGridWidth + static_cast<std::size_t>(x);
            return item < pixels.size() ? std::optional<std::size_t>(pixels[item]) : std::nullopt;
        };
        for (std::uint32_t e = 0; e < most * static_cast<std::uint32_t>(spp); ++e)
            counters.add(ctx.pipeline().dispatchCoherent(
                kListGridWidth, rows, ctx.args(kRayOcclusion),
                [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
                    const std::optional<std::size_t> i = pixelOf(x, y);
                    if (!i || e >= counts[*i] * static_cast<std::uint32_t>(spp)) return std::nullopt;
                    std::optional<tracer::RayDesc> ray = aoRay(*i, static_cast<std::uint32_t>(spp) + e);
                    if (ray) ++tally.tested[*i];
                    return ray;
                },
                [&](int x, int y, const HitPayload& p) { tally.record(*pixelOf(x, y), p); },
                tracer::RayCoherence::Incoherent));
    }

    for (std::size_t i = 0; i < n; ++i) {
        if (!tally.tested[i]) continue;
        visibility[i] = tally.visibility(i);
        hitT[i] = tally.meanOccluderDistance(i, radius);
    }
    return bytes;
}

}  // namespace rtlab::shaders::detail
