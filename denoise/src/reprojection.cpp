#include <rtlab/denoise/reprojection.hpp>

#include "detail.hpp"

#include <cmath>
#include <stdexcept>

namespace rtlab::denoise {

std::size_t Reprojection::validCount() const {
    std::size_t n = 0;
    for (std::uint8_t v : valid) n += v ? 1 : 0;
    return n;
}

Reprojection reproject(const GuideBuffers& cur, const GuideBuffers& prev, const ReprojectionParams& params) {
    std::vector<vec2> scratch;
    const std::vector<vec2>& grad = detail::gradientOf(cur, scratch);
    prev.validate();
    if (cur.width != prev.width || cur.height != prev.height)
        throw std::invalid_argument("denoise::reproject: current and previous guides differ in size");

    Reprojection r;
    r.width = cur.width;
    r.height = cur.height;
    r.taps.assign(cur.pixelCount(), ReprojectionTaps{});
    r.valid.assign(cur.pixelCount(), 0);
    const int w = cur.width, h = cur.height;

    detail::forEachPixel(w, h, [&](int x, int y, std::size_t i) {
        const vec2 pos = vec2(static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f) + cur.motion[i];
        // Off screen (and NaN) -> no history.
        if (!(pos.x >= 0.f && pos.x < static_cast<float>(w) && pos.y >= 0.f && pos.y < static_cast<float>(h))) return;
        const float qx = pos.x - 0.5f, qy = pos.y - 0.5f;
        const float fx0 = std::floor(qx), fy0 = std::floor(qy);
        const int x0 = static_cast<int>(fx0), y0 = static_cast<int>(fy0);
        const float fx = qx - fx0, fy = qy - fy0;
        const float bilinear[4] = {(1.f - fx) * (1.f - fy), fx * (1.f - fy), (1.f - fx) * fy, fx * fy};
        const int ox[4] = {0, 1, 0, 1}, oy[4] = {0, 0, 1, 1};

        const bool sky = cur.isSky(i);
        const int id = cur.meshId[i];
        const float z = cur.depth[i];
        const vec3 n = cur.normal[i];
        const float tolerance =
            params.depthThreshold * (std::fabs(grad[i].x) + std::fabs(grad[i].y) + params.depthEpsilon);

        ReprojectionTaps t;
        float sum = 0.f;
        for (int k = 0; k < 4; ++k) {
            const int px = x0 + ox[k], py = y0 + oy[k];
            if (bilinear[k] <= 0.f || px < 0 || py < 0 || px >= w || py >= h) continue;
            const std::size_t j = static_cast<std::size_t>(py) * static_cast<std::size_t>(w) + px;
            if (prev.meshId[j] != id) continue;
            if (!sky) {
                if (!(std::fabs(z - prev.depth[j]) <= tolerance)) continue;
                if (!(glm::dot(n, prev.normal[j]) >= params.normalThreshold)) continue;
            }
            t.index[k] = static_cast<std::uint32_t>(j);
            t.weight[k] = bilinear[k];
            sum += bilinear[k];
        }
        if (!(sum >= params.minWeight) || !(sum > 0.f)) return;
        for (float& wk : t.weight) wk = wk / sum;
        r.taps[i] = t;
        r.valid[i] = 1;
    });
    return r;
}

namespace {

template <class T>
void gatherImpl(const Reprojection& r, std::span<const T> previous, std::span<T> out, T invalidValue) {
    const std::size_t n = detail::pixelCount(r.width, r.height);
    detail::checkSize(r.taps.size(), n, "Reprojection::taps");
    detail::checkSize(r.valid.size(), n, "Reprojection::valid");
    detail::checkSize(previous.size(), n, "gather: previous");
    detail::checkSize(out.size(), n, "gather: out");
    detail::forEachPixel(r.width, r.height, [&](int, int, std::size_t i) {
        if (!r.valid[i]) {
            out[i] = invalidValue;
            return;
        }
        const ReprojectionTaps& t = r.taps[i];
        T acc = T(0.f);
        for (int k = 0; k < 4; ++k)
            if (t.weight[k] > 0.f) acc += t.weight[k] * previous[t.index[k]];
        out[i] = acc;
    });
}

}  // namespace

void gather(const Reprojection& r, std::span<const float> previous, std::span<float> out, float invalidValue) {
    gatherImpl<float>(r, previous, out, invalidValue);
}
void gather(const Reprojection& r, std::span<const vec2> previous, std::span<vec2> out, vec2 invalidValue) {
    gatherImpl<vec2>(r, previous, out, invalidValue);
}
void gather(const Reprojection& r, std::span<const vec3> previous, std::span<vec3> out, vec3 invalidValue) {
    gatherImpl<vec3>(r, previous, out, invalidValue);
}

}  // namespace rtlab::denoise
