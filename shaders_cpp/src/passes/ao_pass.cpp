// Ambient occlusion: cosine-hemisphere rays around the shading normal,
// limited to RenderSettings::aoRadius; visibility and the nearest occluder's
// distance (a closest-hit query, so the distance is the same on every back
// end; a first-hit query would report whichever occluder traversal met first).
// Contact sampling: after the spp samples of every pixel, the pixels near a
// contact (RenderSettings::aoContactExtraSamples) get more, traced as one
// compact list so that the rest of the image costs nothing.
#include "../lighting.hpp"

#include <rtlab/core/parallel.hpp>
#include <utility>

namespace rtlab::shaders::detail {

std::vector<std::uint8_t> aoContactPixels(int width, int height, std::span<const float> occluderDistance,
                                          std::span<const std::uint8_t> geometry, float nearDistance) {
    const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    std::vector<std::uint8_t> flagged(n, 0);
    if (occluderDistance.size() != n || geometry.size() != n) return flagged;
    const auto index = [&](int x, int y) { return static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + x; };
    parallelForEach(static_cast<std::size_t>(height), [&](std::size_t row) {
        const int y = static_cast<int>(row);
        for (int x = 0; x < width; ++x) {
            if (!geometry[index(x, y)]) continue;
            bool found = false;
            for (int qy = std::max(0, y - kAoContactWindow); qy <= std::min(height - 1, y + kAoContactWindow) && !found; ++qy)
                for (int qx = std::max(0, x - kAoContactWindow); qx <= std::min(width - 1, x + kAoContactWindow) && !found; ++qx)
                    found = (qx != x || qy != y) && occluderDistance[index(qx, qy)] < nearDistance;
            flagged[index(x, y)] = found;
        }
    });
    return flagged;
}

namespace {

// The extra samples are traced on a grid this wide (item = row x width + column).
constexpr int kListGridWidth = 64;
// At most this many contact samples per geometry pixel and sample on
// average: where contacts are everywhere (a hairball, dense foliage) the
// per-pixel count falls so that AO costs at most three times its uniform
// rays (showcase flags 21 % of the pixels at 96x54, 12 % at 320x180).
constexpr std::size_t kContactBudgetPerPixel = 2;

}  // namespace

std::uint64_t runAmbientOcclusionPass(RenderContext& ctx, Image& out, tracer::TraceCounters& counters) {
    const std::size_t n = ctx.gbuffer.size();
    const int spp = std::max(ctx.settings.spp, 1);
    const float radius = ctx.settings.aoRadius;
    float* visibility = out.addChannel("ao.V", 1.f);
    float* hitT = out.addChannel("ao.hitT", 0.f);
    VisibilityTally tally(n);
    // Sample s of pixel i: a cosine direction, or nullopt where nothing is traced.
    const auto aoRay = [&](std::size_t i, std::uint32_t s) -> std::optional<tracer::RayDesc> {
        const GPixel& g = ctx.gbuffer[i];
        if (!g.hit || !(radius > 0.f)) return std::nullopt;
        const SampleKey key = ctx.key(i, s, stream::kAmbientOcclusion);
        const vec3 dir =
            cosineDirectionAbove(g.normal, g.geometricNormal, vec2(sampleUniform(key, 0), sampleUniform(key, 1)));
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

    // Step: contact sampling. Samples spp .. spp + extra - 1 of the pixels
    // near a contact, as one list (a pixel's samples adjacent, so a packet
    // shares its origin); each result lands in its own slot and is tallied
    // in sample order afterwards (the same sums for any thread count).
    const int perSample = std::max(ctx.settings.aoContactExtraSamples, 0);
    if (perSample > 0 && radius > 0.f) {
        // The mean occluder distance each pixel saw (+inf: none) decides its neighbours' counts.
        std::vector<float> occluderDistance(n, kInfinity);
        std::vector<std::uint8_t> geometry(n, 0);
        for (std::size_t i = 0; i < n; ++i) {
            geometry[i] = ctx.gbuffer[i].hit;
            if (tally.occluded[i]) occluderDistance[i] = tally.meanOccluderDistance(i, kInfinity);
        }
        const std::vector<std::uint8_t> flagged =
            aoContactPixels(ctx.width, ctx.height, occluderDistance, geometry,
                            std::max(ctx.settings.aoContactFraction, 0.f) * radius);
        // Step: within the budget, the same count for every flagged pixel.
        std::size_t geometryPixels = 0, flaggedPixels = 0;
        for (std::size_t i = 0; i < n; ++i) geometryPixels += geometry[i], flaggedPixels += flagged[i];
        const std::size_t affordable =
            flaggedPixels ? kContactBudgetPerPixel * geometryPixels / flaggedPixels : std::size_t(perSample);
        const int extra = static_cast<int>(std::min<std::size_t>(std::size_t(perSample), affordable)) * spp;
        // The list: (pixel, sample index), a pixel's samples adjacent.
        std::vector<std::pair<std::uint32_t, std::uint32_t>> list;
        for (std::size_t i = 0; i < n; ++i)
            if (flagged[i])
                for (int e = 0; e < extra; ++e)
                    list.emplace_back(static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(spp + e));
        const std::size_t items = list.size();
        if (items > 0) {
            struct Result {
                bool traced = false, hit = false;
                float t = 0.f;
            };
            std::vector<Result> results(items);
            const int rows = static_cast<int>((items + kListGridWidth - 1) / kListGridWidth);
            const auto itemOf = [&](int x, int y) { return static_cast<std::size_t>(y) * kListGridWidth + x; };
            counters.add(ctx.pipeline().dispatchCoherent(
                kListGridWidth, rows, ctx.args(kRayOcclusion),
                [&](int x, int y, HitPayload&) -> std::optional<tracer::RayDesc> {
                    const std::size_t item = itemOf(x, y);
                    if (item >= items) return std::nullopt;
                    return aoRay(list[item].first, list[item].second);
                },
                [&](int x, int y, const HitPayload& p) {
                    results[itemOf(x, y)] = Result{true, p.hit, p.t};
                },
                tracer::RayCoherence::Incoherent));
            for (std::size_t item = 0; item < items; ++item) {
                if (!results[item].traced) continue;
                const std::size_t i = list[item].first;
                HitPayload p;
                p.hit = results[item].hit;
                p.t = results[item].t;
                ++tally.tested[i];
                tally.record(i, p);
            }
        }
    }

    for (std::size_t i = 0; i < n; ++i) {
        if (!tally.tested[i]) continue;
        visibility[i] = tally.visibility(i);
        hitT[i] = tally.meanOccluderDistance(i, radius);
    }
    return n * 2 * sizeof(float) + tally.bytes();
}

}  // namespace rtlab::shaders::detail
