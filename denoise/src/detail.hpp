#pragma once
// Private helpers of the denoise stages.
#include <rtlab/core/parallel.hpp>
#include <rtlab/denoise/common.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace rtlab::denoise::detail {

// Runs f(x, y, index) for every pixel, in fixed 16x16 tiles, in parallel.
// Each call must write only its own pixel's outputs and read only inputs, so
// the result does not depend on the thread count.
template <class F>
void forEachPixel(int width, int height, F&& f) {
    if (width <= 0 || height <= 0) return;
    const std::vector<Tile> tiles = makeTiles(width, height, 16);
    parallelForEach(tiles.size(), [&](std::size_t t) {
        const Tile& tile = tiles[t];
        for (int y = tile.y0; y < tile.y1; ++y)
            for (int x = tile.x0; x < tile.x1; ++x)
                f(x, y, static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + static_cast<std::size_t>(x));
    });
}

// Runs f(i) for i in [0, count), in fixed chunks, in parallel.
template <class F>
void forEachIndex(std::size_t count, F&& f) {
    parallelForChunks(count, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) f(i);
    });
}

inline std::size_t pixelCount(int width, int height) {
    if (width < 0 || height < 0) throw std::invalid_argument("denoise: negative image size");
    return static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
}

// Throws std::invalid_argument naming `what` when size != expected.
inline void checkSize(std::size_t size, std::size_t expected, const char* what) {
    if (size != expected)
        throw std::invalid_argument(std::string("denoise: ") + what + " has " + std::to_string(size) +
                                    " elements, expected " + std::to_string(expected));
}

// Clamps to [lo, hi]; NaN maps to lo.
inline float clampNaNLow(float v, float lo, float hi) {
    if (!(v > lo)) return lo;
    return v < hi ? v : hi;
}

// exp(-e) for e >= 0, 0 for huge or NaN e.
inline float expNeg(float e) {
    if (!(e < 87.f)) return 0.f;
    return std::exp(-(e > 0.f ? e : 0.f));
}

// A guide's normal of unit length: G-buffer normals are unit vectors up to
// round-off and pass unchanged; others are scaled (sanitised; 0 stays 0).
inline vec3 guideUnitNormal(const vec3& normal) {
    const float l2 = normal.x * normal.x + normal.y * normal.y + normal.z * normal.z;
    if (l2 > 1.f - 1e-6f && l2 < 1.f + 1e-6f) return normal;
    const vec3 n = sanitize(normal);
    const float m = std::max(std::fabs(n.x), std::max(std::fabs(n.y), std::fabs(n.z)));
    if (!(m > 0.f)) return vec3(0.f);
    const vec3 s = n / m;  // no overflow in the squares
    return s / std::sqrt(s.x * s.x + s.y * s.y + s.z * s.z);
}

// Normal edge-stopping weight max(0, n.n')^sigmaN (NaN -> 0). Integer
// exponents up to 4096 (the paper's 128 among them) use exact repeated
// squaring instead of std::pow, which is several times slower.
class NormalWeight {
public:
    explicit NormalWeight(float sigmaN)
        : sigma_(sigmaN > 0.f ? sigmaN : 0.f),
          integer_(sigma_ <= 4096.f && std::floor(sigma_) == sigma_ ? static_cast<unsigned>(sigma_) : 0u),
          isInteger_(sigma_ <= 4096.f && std::floor(sigma_) == sigma_) {}

    float operator()(const vec3& n, const vec3& nq) const {
        const float d = clampNaNLow(glm::dot(n, nq), 0.f, 1.f);
        if (sigma_ == 0.f || d >= 1.f) return 1.f;
        if (d <= 0.f) return 0.f;
        if (!isInteger_) return std::pow(d, sigma_);
        float r = 1.f, b = d;
        for (unsigned e = integer_; e != 0u; e >>= 1u) {
            if (e & 1u) r *= b;
            b *= b;
        }
        return r;
    }

private:
    float sigma_;
    unsigned integer_;
    bool isInteger_;
};

// The depth edge-stopping term |z - zq| / (sigmaZ |grad . offset| + eps * |z|)
// of the paper (offset in pixels); the caller takes exp(-term).
inline float depthTerm(float z, float zq, const vec2& grad, const vec2& offset, float sigmaZ, float relEps) {
    const float num = std::fabs(z - zq);
    if (num == 0.f) return 0.f;
    const float den = sigmaZ * std::fabs(grad.x * offset.x + grad.y * offset.y) + relEps * std::fabs(z);
    if (!(den > 0.f)) return kInfinity;
    return num / den;
}

}  // namespace rtlab::denoise::detail

#include <rtlab/denoise/guides.hpp>

namespace rtlab::denoise::detail {

// The guides' depth gradient, computed into `scratch` when the guides carry
// none. Validates the guides.
inline const std::vector<vec2>& gradientOf(const GuideBuffers& g, std::vector<vec2>& scratch) {
    g.validate();
    if (!g.depthGrad.empty()) return g.depthGrad;
    scratch = depthGradient(g);
    return scratch;
}

}  // namespace rtlab::denoise::detail
