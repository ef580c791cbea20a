#include <rtlab/shaders_cpp/sampling.hpp>

#include <rtlab/core/rng.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace rtlab::shaders {
namespace {

// NaN-safe clamp (std::fmin/fmax return the non-NaN operand, so NaN -> lo).
float clampf(float v, float lo, float hi) { return std::fmin(std::fmax(v, lo), hi); }
float clampU(float u) { return clampf(u, 0.f, kOneMinusEpsilon); }
float clampAlpha(float alpha) { return clampf(alpha, kMinGgxAlpha, 1.f); }

// Divides v by its largest |component| so that squares neither overflow nor
// underflow; false for zero or non-finite v.
bool prescale(vec3& v) {
    const float m = std::fmax(std::fabs(v.x), std::fmax(std::fabs(v.y), std::fabs(v.z)));
    if (!(m > 0.f) || !std::isfinite(m)) return false;
    v /= m;
    return true;
}

vec3 safeNormalize(vec3 v, vec3 fallback) {
    if (!prescale(v)) return fallback;
    return v / std::sqrt(glm::dot(v, v));
}

bool sameHemisphere(const vec3& a, const vec3& b) { return (a.z > 0.f && b.z > 0.f) || (a.z < 0.f && b.z < 0.f); }

// sqrt(cos^2 + alpha^2 sin^2) for a unit (or prescaled) v: the Smith
// Lambda(v) = (A / |cos| - 1) / 2 without the division by cos.
float smithA(const vec3& v, float alpha2) { return std::sqrt(v.z * v.z + alpha2 * (v.x * v.x + v.y * v.y)); }

// G2 / G1(wo) for unit wo, wi in the same hemisphere, in a form that stays
// finite at wo.z = 0: |wi.z| (|wo.z| + Ao) / (Ao |wi.z| + Ai |wo.z|).
float ggxG2OverG1(const vec3& wo, const vec3& wi, float alpha) {
    const float a2 = alpha * alpha;
    const float oz = std::fabs(wo.z), iz = std::fabs(wi.z);
    const float ao = smithA(wo, a2), ai = smithA(wi, a2);
    const float den = ao * iz + ai * oz;
    return den > 0.f ? std::fmin(iz * (oz + ao) / den, 1.f) : 0.f;
}

float radicalInverse2(std::uint32_t bits) {
    return std::fmin(static_cast<float>(reverseBits(bits)) * 0x1p-32f, kOneMinusEpsilon);
}

// Split-sum table: kTableSize x kTableSize nodes at NdotV = i / (size-1),
// roughness = j / (size-1); each node integrates with kTableSamples
// Hammersley points through VNDF sampling, where the weight of a reflected
// sample is G2/G1 (Heitz 2018, eq. 19), split into the parts multiplying
// f0 (1 - Fc) and 1 (Fc), Fc = (1 - wo.h)^5.
constexpr int kTableSize = 32;
constexpr int kTableSamples = 1024;

using SplitSumTable = std::array<vec2, kTableSize * kTableSize>;

SplitSumTable buildSplitSumTable() {
    SplitSumTable table{};
    for (int j = 0; j < kTableSize; ++j) {
        const float alpha = ggxAlpha(static_cast<float>(j) / (kTableSize - 1));
        for (int i = 0; i < kTableSize; ++i) {
            const float cosO = static_cast<float>(i) / (kTableSize - 1);
            const vec3 wo(std::sqrt(std::fmax(0.f, 1.f - cosO * cosO)), 0.f, cosO);
            double scale = 0.0, bias = 0.0;
            for (int k = 0; k < kTableSamples; ++k) {
                const vec2 u((k + 0.5f) / kTableSamples, radicalInverse2(static_cast<std::uint32_t>(k)));
                const vec3 h = sampleGgxVisibleNormal(wo, alpha, u);
                const vec3 wi = reflectAbout(wo, h);
                if (!(wi.z > 0.f)) continue;
                const float w = ggxG2OverG1(wo, wi, alpha);
                const float m = 1.f - clampf(glm::dot(wo, h), 0.f, 1.f);
                const float fc = m * m * m * m * m;
                scale += w * (1.f - fc);
                bias += w * fc;
            }
            const float x = clampf(static_cast<float>(scale / kTableSamples), 0.f, 1.f);
            const float y = clampf(static_cast<float>(bias / kTableSamples), 0.f, 1.f - x);
            table[static_cast<std::size_t>(j) * kTableSize + i] = vec2(x, y);
        }
    }
    return table;
}

void checkTile(std::size_t size, int n) {
    if (n < 1 || size != static_cast<std::size_t>(n + 2) * static_cast<std::size_t>(n + 2))
        throw std::invalid_argument("ddgiFillTileBorder: tile of " + std::to_string(size) +
                                    " texels does not match an interior of " + std::to_string(n) + "^2 plus border");
}

// Octahedral wrap: a texel just outside an edge is the interior texel across
// the edge mirrored about the edge's midpoint; a corner is the opposite corner.
template <typename T>
void fillBorder(std::span<T> tile, int n) {
    checkTile(tile.size(), n);
    const std::size_t w = static_cast<std::size_t>(n) + 2;
    auto at = [&](int x, int y) -> T& { return tile[static_cast<std::size_t>(y) * w + static_cast<std::size_t>(x)]; };
    for (int k = 1; k <= n; ++k) {
        at(k, 0) = at(n + 1 - k, 1);      // top edge
        at(k, n + 1) = at(n + 1 - k, n);  // bottom edge
        at(0, k) = at(1, n + 1 - k);      // left edge
        at(n + 1, k) = at(n, n + 1 - k);  // right edge
    }
    at(0, 0) = at(n, n);
    at(n + 1, 0) = at(1, n);
    at(0, n + 1) = at(n, 1);
    at(n + 1, n + 1) = at(1, 1);
}

}  // namespace

// ---------------------------------------------------------------- frames --

Frame makeFrame(vec3 n) {
    n = safeNormalize(n, vec3(0.f, 0.f, 1.f));
    // Duff et al. 2017, listing 3: one sign select, no singularity at either pole.
    const float sign = std::copysign(1.f, n.z);
    const float a = -1.f / (sign + n.z);
    const float b = n.x * n.y * a;
    return {vec3(1.f + sign * n.x * n.x * a, sign * b, -sign * n.x), vec3(b, sign + n.y * n.y * a, -n.y), n};
}

vec3 toLocal(const Frame& f, vec3 v) { return {glm::dot(v, f.t), glm::dot(v, f.b), glm::dot(v, f.n)}; }
vec3 toWorld(const Frame& f, vec3 v) { return v.x * f.t + v.y * f.b + v.z * f.n; }

// -------------------------------------------------------------- sampling --

vec3 sampleCosineHemisphere(vec2 u) {
    // Concentric map of u to the unit disk (Shirley & Chiu 1997).
    const vec2 o = 2.f * vec2(clampU(u.x), clampU(u.y)) - 1.f;
    vec2 d(0.f);
    if (o.x != 0.f || o.y != 0.f) {
        const bool xMajor = std::fabs(o.x) > std::fabs(o.y);
        const float r = xMajor ? o.x : o.y;
        const float theta = xMajor ? 0.25f * kPi * (o.y / o.x) : 0.5f * kPi - 0.25f * kPi * (o.x / o.y);
        d = r * vec2(std::cos(theta), std::sin(theta));
    }
    // Malley's method: lift the disk point onto the hemisphere.
    return {d.x, d.y, std::sqrt(std::fmax(0.f, 1.f - d.x * d.x - d.y * d.y))};
}

float cosineHemispherePdf(float cosTheta) { return std::fmax(cosTheta, 0.f) * (1.f / kPi); }

vec3 sampleUniformSphere(vec2 u) {
    const float z = 1.f - 2.f * clampU(u.x);
    const float r = std::sqrt(std::fmax(0.f, 1.f - z * z));
    const float phi = 2.f * kPi * clampU(u.y);
    return {r * std::cos(phi), r * std::sin(phi), z};
}

float uniformSpherePdf() { return 1.f / (4.f * kPi); }

vec3 sampleUniformCone(vec2 u, float cosThetaMax) {
    const float c = clampf(cosThetaMax, -1.f, 1.f);
    const float u0 = clampU(u.x);
    // cos(theta) uniform in [cosThetaMax, 1].
    const float cosTheta = (1.f - u0) + u0 * c;
    const float sinTheta = std::sqrt(std::fmax(0.f, 1.f - cosTheta * cosTheta));
    const float phi = 2.f * kPi * clampU(u.y);
    return {sinTheta * std::cos(phi), sinTheta * std::sin(phi), cosTheta};
}

float uniformConePdf(float cosThetaMax) {
    const float solidAngle = 2.f * kPi * (1.f - clampf(cosThetaMax, -1.f, 1.f));
    return solidAngle > 1e-30f ? 1.f / solidAngle : 1e30f;
}

// ----------------------------------------------------------------- GGX --

float ggxAlpha(float roughness) {
    const float r = clampf(roughness, 0.f, 1.f);
    return std::fmax(r * r, kMinGgxAlpha);
}

float ggxD(vec3 h, float alpha) {
    const float a2 = clampAlpha(alpha) * clampAlpha(alpha);
    if (!prescale(h)) return 0.f;
    const float l2 = glm::dot(h, h);
    // D = 1 / (pi a^2 cos^4 (1 + tan^2 / a^2)^2) = 1 / (pi a^2 (sin^2 / a^2 + cos^2)^2);
    // sin^2 from x, y avoids the cancellation of 1 - cos^2 near the peak.
    const float t = (h.x * h.x + h.y * h.y) / (l2 * a2) + h.z * h.z / l2;
    return 1.f / (kPi * a2 * t * t);
}

float ggxG1(vec3 v, float alpha) {
    const float a = clampAlpha(alpha);
    if (!prescale(v)) return 0.f;
    // 1 / (1 + Lambda) = 2 |cos| / (|cos| + sqrt(cos^2 + a^2 sin^2)).
    const float oz = std::fabs(v.z);
    const float den = oz + smithA(v, a * a);
    return den > 0.f ? 2.f * oz / den : 0.f;
}

float ggxG2(vec3 wo, vec3 wi, float alpha) {
    const float a = clampAlpha(alpha);
    if (!prescale(wo) || !prescale(wi)) return 0.f;
    // 1 / (1 + Lambda_o + Lambda_i) over the common denominator 2 |cos_o| |cos_i|.
    const float oz = std::fabs(wo.z), iz = std::fabs(wi.z);
    const float den = smithA(wo, a * a) * iz + smithA(wi, a * a) * oz;
    return den > 0.f ? std::fmin(2.f * oz * iz / den, 1.f) : 0.f;
}

vec3 sampleGgxVisibleNormal(vec3 wo, float alpha, vec2 u) {
    // Double precision: at alpha = kMinGgxAlpha the final un-stretch divides
    // the rounding error of the hemisphere's z by alpha.
    const double a = clampAlpha(alpha);
    const double u0 = clampU(u.x), u1 = clampU(u.y);
    // Treat wo below the surface as its mirror image; flip h back at the end.
    const double side = wo.z < 0.f ? -1.0 : 1.0;
    // Stretch wo into the hemisphere configuration (Heitz 2018, sec. 3.2).
    double vx = a * wo.x, vy = a * wo.y, vz = side * wo.z;
    double len = std::sqrt(vx * vx + vy * vy + vz * vz);
    if (!(len > 0.0) || !std::isfinite(len)) vx = 0.0, vy = 0.0, vz = 1.0, len = 1.0;
    vx /= len, vy /= len, vz /= len;
    // Orthonormal basis around the view direction (sec. 4.1), T1 horizontal.
    const double lensq = vx * vx + vy * vy;
    double t1x = 1.0, t1y = 0.0;
    if (lensq > 0.0) t1x = -vy / std::sqrt(lensq), t1y = vx / std::sqrt(lensq);
    const double t2x = -vz * t1y, t2y = vz * t1x, t2z = vx * t1y - vy * t1x;  // cross(V, T1)
    // Uniform point on the projected disk, warped onto the visible half (sec. 4.2).
    const double r = std::sqrt(u0), phi = 2.0 * 3.14159265358979323846 * u1;
    const double p1 = r * std::cos(phi);
    const double s = 0.5 * (1.0 + vz);
    const double p2 = (1.0 - s) * std::sqrt(std::fmax(0.0, 1.0 - p1 * p1)) + s * r * std::sin(phi);
    // Reproject onto the hemisphere (sec. 4.3).
    const double pz = std::sqrt(std::fmax(0.0, 1.0 - p1 * p1 - p2 * p2));
    const double nx = p1 * t1x + p2 * t2x + pz * vx;
    const double ny = p1 * t1y + p2 * t2y + pz * vy;
    const double nz = p2 * t2z + pz * vz;
    // Un-stretch the normal back to the ellipsoid configuration (sec. 3.4).
    double ex = a * nx, ey = a * ny, ez = std::fmax(0.0, nz);
    const double elen = std::sqrt(ex * ex + ey * ey + ez * ez);
    if (!(elen > 0.0)) return {0.f, 0.f, static_cast<float>(side)};
    ex /= elen, ey /= elen, ez /= elen;
    return {static_cast<float>(ex), static_cast<float>(ey), static_cast<float>(side * ez)};
}

float ggxVisibleNormalPdf(vec3 wo, vec3 h, float alpha) {
    const float a = clampAlpha(alpha);
    if (!prescale(wo)) return 0.f;
    h = safeNormalize(h, vec3(0.f));
    const float cosOH = glm::dot(wo, h);
    const float den = std::fabs(wo.z) + smithA(wo, a * a);
    // Microfacet normals live on wo's side of the surface only.
    if (!sameHemisphere(wo, h) || !(cosOH > 0.f) || !(den > 0.f)) return 0.f;
    // G1(wo) max(0, wo.h) D(h) / |wo.z| with G1 / |wo.z| = 2 / (|wo.z| + A(wo)).
    return 2.f * ggxD(h, a) * (cosOH / den);
}

vec3 reflectAbout(vec3 wo, vec3 h) { return 2.f * glm::dot(wo, h) * h - wo; }

GgxReflectionSample sampleGgxReflection(vec3 wo, float alpha, vec2 u) {
    const float a = clampAlpha(alpha);
    wo = safeNormalize(wo, vec3(0.f, 0.f, 1.f));
    GgxReflectionSample out;
    out.h = sampleGgxVisibleNormal(wo, a, u);
    out.wi = safeNormalize(reflectAbout(wo, out.h), wo);
    if (!sameHemisphere(wo, out.wi)) return out;  // pdf 0
    // pdf_vndf / (4 wo.h) with wo.h cancelled: D(h) / (2 (|wo.z| + A(wo))).
    out.pdf = ggxD(out.h, a) / (2.f * (std::fabs(wo.z) + smithA(wo, a * a)));
    return out;
}

float ggxReflectionPdf(vec3 wo, vec3 wi, float alpha) {
    const float a = clampAlpha(alpha);
    wo = safeNormalize(wo, vec3(0.f));
    wi = safeNormalize(wi, vec3(0.f));
    if (!sameHemisphere(wo, wi)) return 0.f;
    const vec3 h = safeNormalize(wo + wi, vec3(0.f));
    return ggxD(h, a) / (2.f * (std::fabs(wo.z) + smithA(wo, a * a)));
}

float fresnelSchlick(float f0, float cosTheta) {
    const float m = 1.f - clampf(cosTheta, 0.f, 1.f);
    const float m5 = (m * m) * (m * m) * m;
    return f0 + (1.f - f0) * m5;
}

vec3 fresnelSchlick(vec3 f0, float cosTheta) {
    const float m = 1.f - clampf(cosTheta, 0.f, 1.f);
    const float m5 = (m * m) * (m * m) * m;
    return f0 + (vec3(1.f) - f0) * m5;
}

vec2 specularBrdfIntegral(float NdotV, float roughness) {
    static const SplitSumTable table = buildSplitSumTable();
    // Bilinear lookup between the nodes.
    const float x = clampf(NdotV, 0.f, 1.f) * (kTableSize - 1);
    const float y = clampf(roughness, 0.f, 1.f) * (kTableSize - 1);
    const int i = std::min(static_cast<int>(x), kTableSize - 2);
    const int j = std::min(static_cast<int>(y), kTableSize - 2);
    const float fx = x - i, fy = y - j;
    auto node = [&](int ii, int jj) { return table[static_cast<std::size_t>(jj) * kTableSize + ii]; };
    const vec2 lo = glm::mix(node(i, j), node(i + 1, j), fx);
    const vec2 hi = glm::mix(node(i, j + 1), node(i + 1, j + 1), fx);
    return glm::clamp(glm::mix(lo, hi, fy), vec2(0.f), vec2(1.f));
}

// -------------------------------------------------------------- geometry --

vec3 offsetRayOrigin(vec3 p, vec3 ng) {
    constexpr float kOrigin = 1.f / 32.f;         // below this |p|, use a float offset
    constexpr float kFloatScale = 1.f / 65536.f;  // float offset per unit normal
    constexpr float kIntScale = 256.f;            // ULPs per unit normal
    const vec3 n = safeNormalize(ng, vec3(0.f));
    vec3 out;
    for (int k = 0; k < 3; ++k) {
        if (std::fabs(p[k]) < kOrigin) {
            out[k] = p[k] + kFloatScale * n[k];
            continue;
        }
        // Move the magnitude's bit pattern by up to 256 ULPs in n's direction,
        // saturating at the largest finite float.
        const std::uint32_t bits = std::bit_cast<std::uint32_t>(p[k]);
        const std::uint32_t sign = bits & 0x80000000u;
        const std::int64_t ulps = static_cast<std::int64_t>(kIntScale * n[k]);
        const std::int64_t mag = static_cast<std::int64_t>(bits & 0x7fffffffu) + (sign ? -ulps : ulps);
        const std::int64_t clamped = std::clamp<std::int64_t>(mag, 0, 0x7f7fffff);
        out[k] = std::bit_cast<float>(sign | static_cast<std::uint32_t>(clamped));
    }
    return out;
}

vec3 sphericalFibonacci(std::uint32_t i, std::uint32_t n) {
    if (n == 0) return {0.f, 0.f, 1.f};
    i %= n;
    // Golden-angle spiral on equal-area z bands (Keinert et al. 2015, eq. 2).
    constexpr double kInvGolden = 0.61803398874989484820;  // (sqrt(5) - 1) / 2
    const double f = static_cast<double>(i) * kInvGolden;
    const double phi = 2.0 * 3.14159265358979323846 * (f - std::floor(f));
    const double z = 1.0 - (2.0 * i + 1.0) / n;
    const double r = std::sqrt(std::fmax(0.0, 1.0 - z * z));
    return {static_cast<float>(r * std::cos(phi)), static_cast<float>(r * std::sin(phi)), static_cast<float>(z)};
}

vec3 sphericalFibonacci(std::uint32_t i, std::uint32_t n, const mat3& rotation) {
    return safeNormalize(rotation * sphericalFibonacci(i, n), vec3(0.f, 0.f, 1.f));
}

mat3 randomRotation(vec3 u) {
    // Uniform unit quaternion (Shoemake, "Uniform Random Rotations", GG III).
    const float u0 = clampU(u.x), t1 = 2.f * kPi * clampU(u.y), t2 = 2.f * kPi * clampU(u.z);
    const float r1 = std::sqrt(1.f - u0), r2 = std::sqrt(u0);
    const quat q = glm::normalize(quat(r2 * std::cos(t2), r1 * std::sin(t1), r1 * std::cos(t1), r2 * std::sin(t2)));
    return glm::mat3_cast(q);
}

vec2 octEncode(vec3 dir) {
    if (!prescale(dir)) return vec2(0.f);
    // Project onto the octahedron |x| + |y| + |z| = 1, then fold the lower half.
    const vec2 p = vec2(dir.x, dir.y) / (std::fabs(dir.x) + std::fabs(dir.y) + std::fabs(dir.z));
    if (dir.z >= 0.f) return p;
    const float sx = p.x >= 0.f ? 1.f : -1.f, sy = p.y >= 0.f ? 1.f : -1.f;
    return {(1.f - std::fabs(p.y)) * sx, (1.f - std::fabs(p.x)) * sy};
}

vec3 octDecode(vec2 e) {
    e = vec2(clampf(e.x, -1.f, 1.f), clampf(e.y, -1.f, 1.f));
    vec3 v(e.x, e.y, 1.f - std::fabs(e.x) - std::fabs(e.y));
    if (v.z < 0.f) {
        // Unfold the corner triangles onto the lower hemisphere.
        const float sx = v.x >= 0.f ? 1.f : -1.f, sy = v.y >= 0.f ? 1.f : -1.f;
        const float x = (1.f - std::fabs(e.y)) * sx, y = (1.f - std::fabs(e.x)) * sy;
        v.x = x, v.y = y;
    }
    return safeNormalize(v, vec3(0.f, 0.f, 1.f));
}

std::size_t ddgiTileIndex(int x, int y, int interiorSize) {
    return static_cast<std::size_t>(y) * static_cast<std::size_t>(interiorSize + 2) + static_cast<std::size_t>(x);
}

vec3 ddgiTexelDirection(int i, int j, int interiorSize) {
    const int n = std::max(interiorSize, 1);
    i = std::clamp(i, 0, n - 1), j = std::clamp(j, 0, n - 1);
    const float inv = 2.f / static_cast<float>(n);
    return octDecode(vec2((i + 0.5f) * inv - 1.f, (j + 0.5f) * inv - 1.f));
}

vec2 ddgiTileCoord(vec3 dir, int interiorSize) {
    const float n = static_cast<float>(std::max(interiorSize, 1));
    return vec2(1.f) + (octEncode(dir) * 0.5f + 0.5f) * n;
}

void ddgiFillTileBorder(std::span<vec3> tile, int interiorSize) { fillBorder(tile, interiorSize); }
void ddgiFillTileBorder(std::span<vec2> tile, int interiorSize) { fillBorder(tile, interiorSize); }

// ---------------------------------------------------------------- misc --

float powerHeuristic(int nf, float fPdf, int ng, float gPdf) {
    const float f = static_cast<float>(nf) * fPdf, g = static_cast<float>(ng) * gPdf;
    if (!(f > 0.f)) return 0.f;
    if (!(g > 0.f)) return 1.f;
    if (std::isinf(f)) return std::isinf(g) ? 0.5f : 1.f;
    // f^2 / (f^2 + g^2) as 1 / (1 + (g/f)^2): no overflow of the squares.
    const float r = g / f;
    return 1.f / (1.f + r * r);
}

float luminance(vec3 rgb) { return 0.2126f * rgb.r + 0.7152f * rgb.g + 0.0722f * rgb.b; }

vec3 offsetRayOriginByError(vec3 p, vec3 ng, float errorMagnitude) {
    const float len = glm::length(ng);
    if (!(len > 0.f) || !std::isfinite(len) || !isFinite(p)) return p;
    const vec3 n = ng / len;
    // Step: 8 ulps of the error magnitude (2^-20 relative), never below the smallest normal float.
    const float magnitude = std::max({std::abs(errorMagnitude), std::abs(p.x), std::abs(p.y), std::abs(p.z)});
    const float delta = std::max(std::isfinite(magnitude) ? magnitude * 0x1p-20f : 0x1p-20f * 3.4e38f,
                                 std::numeric_limits<float>::min());
    vec3 q;
    for (int a = 0; a < 3; ++a) {
        q[a] = p[a] + delta * n[a];
        // Step: a component the normal points along moves by at least one ulp.
        if (q[a] == p[a] && n[a] != 0.f) q[a] = std::nextafter(p[a], n[a] > 0.f ? kInfinity : -kInfinity);
        if (!std::isfinite(q[a])) q[a] = p[a];
    }
    return q;
}

}  // namespace rtlab::shaders
