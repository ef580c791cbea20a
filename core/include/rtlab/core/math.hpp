#pragma once
// Math vocabulary: GLM types under short names, bounding boxes, TRS helpers.
#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace rtlab {

using vec2 = glm::vec2;
using vec3 = glm::vec3;
using vec4 = glm::vec4;
using ivec2 = glm::ivec2;
using uvec3 = glm::uvec3;
using mat3 = glm::mat3;
using mat4 = glm::mat4;
using quat = glm::quat;

inline constexpr float kPi = 3.14159265358979323846f;
inline constexpr float kInfinity = std::numeric_limits<float>::infinity();

// The sRGB transfer function's inverse: display value (0..1) -> linear.
inline float srgbToLinear(float c) { return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f); }

inline bool isFinite(float v) { return std::isfinite(v); }
inline bool isFinite(const vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
inline bool isFinite(const vec4& v) { return isFinite(vec3(v)) && std::isfinite(v.w); }
inline bool isFinite(const mat4& m) {
    for (int c = 0; c < 4; ++c)
        if (!isFinite(m[c])) return false;
    return true;
}

// The largest absolute row sum of a transform's linear part: how much it can
// lengthen a vector in the max norm (any glm matrix of 3 or more columns).
template <class Mat>
double maxNormGain(const Mat& m) {
    double gain = 0.0;
    for (int row = 0; row < 3; ++row)
        gain = std::max(gain, std::abs(double(m[0][row])) + std::abs(double(m[1][row])) + std::abs(double(m[2][row])));
    return gain;
}

// Axis-aligned bounding box; empty (lo > hi) until something is added.
struct Aabb {
    vec3 lo{kInfinity};
    vec3 hi{-kInfinity};

    void extend(const vec3& p) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    void extend(const Aabb& b) {
        lo = glm::min(lo, b.lo);
        hi = glm::max(hi, b.hi);
    }
    bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
    vec3 center() const { return 0.5f * (lo + hi); }
    vec3 extent() const { return hi - lo; }
    float surfaceArea() const {
        if (empty()) return 0.f;
        const vec3 d = extent();
        return 2.f * (d.x * d.y + d.y * d.z + d.z * d.x);
    }
    Aabb transformed(const mat4& m) const {
        Aabb out;
        if (empty()) return out;
        for (int i = 0; i < 8; ++i) {
            const vec3 corner{(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z};
            out.extend(vec3(m * vec4(corner, 1.f)));
        }
        return out;
    }
};

// Matrix from translation, rotation, scale (glTF order: T * R * S).
inline mat4 composeTrs(const vec3& t, const quat& r, const vec3& s) {
    return glm::translate(mat4(1.f), t) * glm::mat4_cast(r) * glm::scale(mat4(1.f), s);
}

// Rotation taking local -Z to `direction` (unit or not), keeping local +Y as
// close to world `up` as possible; robust when direction is parallel to up.
inline quat orientationLookingAlong(const vec3& direction, const vec3& up = vec3(0.f, 1.f, 0.f)) {
    const vec3 forward = glm::normalize(direction);
    vec3 right = glm::cross(forward, up);
    if (glm::dot(right, right) < 1e-12f) right = glm::cross(forward, vec3(1.f, 0.f, 0.f));
    if (glm::dot(right, right) < 1e-12f) right = glm::cross(forward, vec3(0.f, 0.f, 1.f));
    right = glm::normalize(right);
    const vec3 trueUp = glm::cross(right, forward);
    return glm::quat_cast(mat3(right, trueUp, -forward));
}

}  // namespace rtlab
