#pragma once
// Helpers shared by the denoise tests: synthetic guides and noise.
#include <rtlab/core/rng.hpp>
#include <rtlab/denoise/guides.hpp>

#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

namespace rtlab::denoise::testing {

// A fronto-parallel plane at depth 1, normal +Z, mesh 0, no motion.
inline GuideBuffers flatGuides(int w, int h) { return GuideBuffers(w, h); }

// Uniform noise in [-0.5, 0.5): variance 1/12.
inline float uniformNoise(std::size_t pixel, std::uint32_t frame, std::uint32_t seed = 7, std::uint32_t dim = 0) {
    SampleKey k;
    k.pixel = static_cast<std::uint32_t>(pixel);
    k.frame = frame;
    k.seed = seed;
    return sampleUniform(k, dim) - 0.5f;
}

// Grey (v, v, v) image: luminance equals v.
inline std::vector<vec3> constantImage(std::size_t n, float v) { return std::vector<vec3>(n, vec3(v)); }

// Grey image 1 + amplitude * uniform noise (variance amplitude^2 / 12).
inline std::vector<vec3> noisyGrey(std::size_t n, float mean, float amplitude, std::uint32_t frame,
                                   std::uint32_t seed = 7) {
    std::vector<vec3> img(n);
    for (std::size_t i = 0; i < n; ++i) img[i] = vec3(mean + amplitude * uniformNoise(i, frame, seed));
    return img;
}

inline bool allFinite(std::span<const vec3> v) {
    for (const vec3& c : v)
        if (!std::isfinite(c.x) || !std::isfinite(c.y) || !std::isfinite(c.z)) return false;
    return true;
}
inline bool allFinite(std::span<const float> v) {
    for (float c : v)
        if (!std::isfinite(c)) return false;
    return true;
}

// Sample variance of the red channel over the pixels selected by `keep`.
template <class Keep>
double channelVariance(std::span<const vec3> img, Keep keep) {
    double s = 0, s2 = 0;
    std::size_t n = 0;
    for (std::size_t i = 0; i < img.size(); ++i) {
        if (!keep(i)) continue;
        s += img[i].r;
        s2 += static_cast<double>(img[i].r) * img[i].r;
        ++n;
    }
    if (n == 0) return 0;
    const double m = s / n;
    return s2 / n - m * m;
}

// Largest |a - b| relative to max(1, |b|), over all channels.
inline double maxRelDiff(std::span<const vec3> a, std::span<const vec3> b) {
    double m = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
        for (int c = 0; c < 3; ++c) {
            const double d = std::fabs(static_cast<double>(a[i][c]) - b[i][c]) / std::fmax(1.0, std::fabs(b[i][c]));
            m = std::fmax(m, d);
        }
    return m;
}

}  // namespace rtlab::denoise::testing
