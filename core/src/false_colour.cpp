#include <rtlab/core/image.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace rtlab {

vec3 falseColour(float value, float scaleMax) {
    // Stops in display (sRGB) space, evenly spaced over [0, scaleMax].
    static constexpr std::array<std::array<float, 3>, 7> kStops{{{0.f, 0.f, 0.f},
                                                                 {0.1f, 0.15f, 0.85f},
                                                                 {0.f, 0.8f, 0.9f},
                                                                 {0.1f, 0.85f, 0.2f},
                                                                 {1.f, 0.9f, 0.1f},
                                                                 {0.95f, 0.15f, 0.05f},
                                                                 {1.f, 1.f, 1.f}}};
    if (!std::isfinite(value) || !(scaleMax > 0.f)) return vec3(0.f);
    const float x = std::clamp(value / scaleMax, 0.f, 1.f) * float(kStops.size() - 1);
    const std::size_t i = std::min(static_cast<std::size_t>(x), kStops.size() - 2);
    const float f = x - float(i);
    vec3 display;
    for (int c = 0; c < 3; ++c) display[c] = kStops[i][c] + f * (kStops[i + 1][c] - kStops[i][c]);
    // sRGB decode, so that the PNG encoder's sRGB curve gives back `display`.
    vec3 linear;
    for (int c = 0; c < 3; ++c) linear[c] = srgbToLinear(display[c]);
    return linear;
}

float quantile(const float* values, std::size_t count, double q) {
    std::vector<float> finite;
    finite.reserve(count);
    for (std::size_t i = 0; i < count; ++i)
        if (std::isfinite(values[i])) finite.push_back(values[i]);
    if (finite.empty()) return 0.f;
    const double clamped = std::clamp(q, 0.0, 1.0);
    const auto rank = static_cast<std::size_t>(std::ceil(clamped * double(finite.size())));
    const std::size_t k = rank == 0 ? 0 : rank - 1;
    std::nth_element(finite.begin(), finite.begin() + static_cast<std::ptrdiff_t>(k), finite.end());
    return finite[k];
}

}  // namespace rtlab
