#include "lighting.hpp"

#include <rtlab/core/simd.hpp>

#include <algorithm>
#include <cmath>
#include <optional>

namespace rtlab::shaders::detail {
namespace {

vec3 lightPosition(const ecs::LightSnapshot& l) { return vec3(l.worldFromLight[3]); }
vec3 lightForward(const ecs::LightSnapshot& l) { return -glm::normalize(vec3(l.worldFromLight[2])); }
vec3 emitted(const ecs::LightSnapshot& l) { return l.light.color * l.light.intensity; }

float lightArea(const ecs::LightSnapshot& l) {
    if (l.light.type == ecs::LightType::Rect) return std::abs(l.light.size.x * l.light.size.y);
    return 4.f * kPi * l.light.radius * l.light.radius;
}

// A rect light's world area: its size times the scale of its transform's x and y axes.
float rectWorldArea(const ecs::LightSnapshot& l) {
    return lightArea(l) * glm::length(glm::cross(vec3(l.worldFromLight[0]), vec3(l.worldFromLight[1])));
}

// 1 - cos(theta_max) of the cone a sphere of radius r subtends at squared
// distance dist2 > r^2, as sin^2 / (1 + cos): the direct form loses every
// digit for small or distant spheres.
float sphereConeOneMinusCos(float dist2, float r) {
    const float sinMax2 = r * r / dist2;
    const float cosMax = std::sqrt(std::max(0.f, 1.f - sinMax2));
    return sinMax2 / (1.f + cosMax);
}

}  // namespace

ShadingPoint shadingPointOf(const GPixel& g) {
    ShadingPoint sp;
    sp.position = g.position;
    sp.normal = g.normal;
    sp.geometricNormal = g.geometricNormal;
    sp.wo = g.viewDir;
    sp.albedo = g.albedo;
    sp.roughness = g.roughness;
    sp.metalness = g.metalness;
    sp.transmission = g.transmission;
    sp.errorScale = g.errorScale;
    finishShadingPoint(sp);
    return sp;
}

ShadingPoint shadingPointOf(const HitPayload& hit, const ecs::Material& m, const vec3& wo) {
    ShadingPoint sp;
    sp.position = hit.position;
    sp.normal = hit.shadingNormal;
    sp.geometricNormal = hit.geometricNormal;
    sp.wo = wo;
    sp.albedo = hit.albedo;
    sp.roughness = glm::clamp(m.roughness, 0.f, 1.f);
    sp.metalness = glm::clamp(m.metallic, 0.f, 1.f);
    sp.transmission = glm::clamp(m.transmission, 0.f, 1.f);
    sp.errorScale = hit.errorScale;
    finishShadingPoint(sp);
    return sp;
}

void finishShadingPoint(ShadingPoint& sp) {
    sp.frame = makeFrame(sp.normal);
    sp.woLocal = toLocal(sp.frame, sp.wo);
}

vec3 specularF0(const vec3& albedo, float metalness) { return glm::mix(vec3(0.04f), albedo, metalness); }
vec3 specularF0(const ShadingPoint& sp) { return specularF0(sp.albedo, sp.metalness); }

namespace {

// The specular lobe's pick probability in sampleBrdf; < 0 when nothing can be sampled.
float specularLobeProbability(const ShadingPoint& sp) {
    const float cosO = std::max(sp.woLocal.z, 0.f);
    if (!(cosO > 0.f)) return -1.f;
    const float diffuse = (1.f - sp.metalness) * (1.f - sp.transmission) * luminance(sp.albedo);
    const float specular = luminance(fresnelSchlick(specularF0(sp), cosO));
    if (!(diffuse + specular > 0.f)) return -1.f;
    return specular / (diffuse + specular);
}

float mixturePdf(const ShadingPoint& sp, float pSpecular, const vec3& wiLocal) {
    return pSpecular * ggxReflectionPdf(sp.woLocal, wiLocal, ggxAlpha(sp.roughness)) +
           (1.f - pSpecular) * cosineHemispherePdf(wiLocal.z);
}

}  // namespace

BrdfSample sampleBrdf(const ShadingPoint& sp, float uLobe, vec2 u) {
    BrdfSample b;
    const float pSpecular = specularLobeProbability(sp);
    if (pSpecular < 0.f) return b;
    // Step: direction from the picked lobe.
    vec3 wiLocal;
    if (uLobe < pSpecular) {
        const GgxReflectionSample rs = sampleGgxReflection(sp.woLocal, ggxAlpha(sp.roughness), u);
        if (!(rs.pdf > 0.f)) return b;
        wiLocal = rs.wi;
    } else {
        wiLocal = sampleCosineHemisphere(u);
    }
    // Step: the mixture pdf of both lobes.
    b.pdf = mixturePdf(sp, pSpecular, wiLocal);
    b.direction = glm::normalize(toWorld(sp.frame, wiLocal));
    b.valid = b.pdf > 0.f && std::isfinite(b.pdf) && glm::dot(b.direction, sp.geometricNormal) > 0.f;
    return b;
}

BrdfSample sampleSpecularLobe(const ShadingPoint& sp, vec2 u) {
    BrdfSample b;
    if (!(sp.woLocal.z > 0.f)) return b;
    const GgxReflectionSample rs = sampleGgxReflection(sp.woLocal, ggxAlpha(sp.roughness), u);
    b.pdf = rs.pdf;
    b.direction = glm::normalize(toWorld(sp.frame, rs.wi));
    b.valid = b.pdf > 0.f && std::isfinite(b.pdf) && glm::dot(b.direction, sp.geometricNormal) > 0.f;
    return b;
}

float specularLobePdf(const ShadingPoint& sp, const vec3& wi) {
    if (!(sp.woLocal.z > 0.f) || glm::dot(wi, sp.geometricNormal) <= 0.f) return 0.f;
    const float pdf = ggxReflectionPdf(sp.woLocal, toLocal(sp.frame, wi), ggxAlpha(sp.roughness));
    return pdf > 0.f ? pdf : 0.f;
}

vec3 evalDiffuseCos(const ShadingPoint& sp, const vec3& wi) {
    const float cosI = glm::dot(sp.normal, wi);
    if (!(cosI > 0.f) || glm::dot(sp.geometricNormal, wi) <= 0.f) return vec3(0.f);
    return (1.f - sp.metalness) * (1.f - sp.transmission) * sp.albedo * (cosI / kPi);
}

vec3 evalSpecularCos(const ShadingPoint& sp, const vec3& wi) {
    const float cosI = glm::dot(sp.normal, wi);
    const float cosO = glm::dot(sp.normal, sp.wo);
    if (!(cosI > 0.f) || glm::dot(sp.geometricNormal, wi) <= 0.f || !(cosO > 0.f)) return vec3(0.f);
    // Step: GGX specular D G F / (4 cosI cosO) x cosI, in the shading frame.
    const vec3& wo = sp.woLocal;
    const vec3 wiLocal = toLocal(sp.frame, wi);
    const vec3 h = glm::normalize(wo + wiLocal);
    const float alpha = ggxAlpha(sp.roughness);
    const vec3 F = fresnelSchlick(specularF0(sp), glm::dot(wiLocal, h));
    const float spec = ggxD(h, alpha) * ggxG2(wo, wiLocal, alpha) / (4.f * std::max(cosO, 1e-6f));
    return std::isfinite(spec) ? F * spec : vec3(0.f);
}

vec3 evalBrdfCos(const ShadingPoint& sp, const vec3& wi) { return evalDiffuseCos(sp, wi) + evalSpecularCos(sp, wi); }

tracer::RayDesc shadowRayToward(const LightSample& ls, const vec3& p, const vec3& ng, float errorScale) {
    const vec3 origin = rayOriginLeaving(p, ng, ls.direction, errorScale);
    if (!std::isfinite(ls.distance)) return tracer::RayDesc{origin, 0.f, ls.direction, kInfinity};
    const vec3 toTarget = ls.direction * ls.distance - (origin - p);
    const float length = glm::length(toTarget);
    if (!(length > 0.f) || !std::isfinite(length)) return tracer::RayDesc{origin, 0.f, ls.direction, ls.distance};
    return tracer::RayDesc{origin, 0.f, toTarget / length, length};
}

float penumbraWidth(const ecs::LightSnapshot& l, const vec3& p, float occluderDistance) {
    if (!(occluderDistance > 0.f)) return 0.f;
    // Step: the light's size in world units (its transform may scale it).
    float size = 0.f;
    if (l.light.type == ecs::LightType::Rect) {
        const float sx = l.light.size.x * glm::length(vec3(l.worldFromLight[0]));
        const float sy = l.light.size.y * glm::length(vec3(l.worldFromLight[1]));
        size = std::sqrt(sx * sx + sy * sy);
    } else {
        size = 2.f * std::max(l.light.radius, 0.f);
    }
    // Step: similar triangles, light -> occluder -> receiver.
    const float toLight = glm::length(lightPosition(l) - p);
    const float occluderToLight = std::max(toLight - occluderDistance, 1e-6f * toLight);
    const float width = size * occluderDistance / occluderToLight;
    return std::isfinite(width) ? std::min(width, 1e6f * size) : 0.f;
}

LightSample sampleAreaLight(const ecs::LightSnapshot& l, const vec3& p, vec2 u) {
    LightSample s;
    if (l.light.type == ecs::LightType::Rect) {
        // Step: uniform point on the rectangle; area pdf -> solid angle.
        const vec3 ax = vec3(l.worldFromLight[0]), ay = vec3(l.worldFromLight[1]);
        // Relative to p first: far from the origin, absolute positions lose the light's size to rounding.
        const vec3 d = (lightPosition(l) - p) + (u.x - 0.5f) * l.light.size.x * ax + (u.y - 0.5f) * l.light.size.y * ay;
        const float dist2 = glm::dot(d, d);
        if (!(dist2 > 0.f)) return s;
        const float dist = std::sqrt(dist2);
        s.direction = d / dist;
        s.distance = dist;
        const float cosLight = glm::dot(-s.direction, lightForward(l));
        if (!(cosLight > 0.f)) return s;  // the back of a one-sided panel
        const float area = rectWorldArea(l);
        s.radianceOverPdf = emitted(l) * (cosLight * area / dist2);
        s.pdf = dist2 / (cosLight * area);
        s.valid = std::isfinite(s.radianceOverPdf.x) && area > 0.f;
        return s;
    }
    // Step: sphere light — uniform in the cone it subtends. 1 - cos(theta_max)
    // as sin^2 / (1 + cos): the direct form loses every digit for small or distant spheres.
    const vec3 c = lightPosition(l);
    const vec3 d = c - p;
    const float dist2 = glm::dot(d, d);
    const float r = std::max(l.light.radius, 0.f);
    if (!(dist2 > r * r)) return s;  // inside the light
    const float dist = std::sqrt(dist2);
    const float oneMinusCosMax = sphereConeOneMinusCos(dist2, r);
    const float oneMinusCos = std::min(u.x, kOneMinusEpsilon) * oneMinusCosMax;
    const float sinTheta = std::sqrt(std::max(0.f, oneMinusCos * (2.f - oneMinusCos)));
    const float phi = 2.f * kPi * u.y;
    const Frame frame = makeFrame(d / dist);
    s.direction =
        glm::normalize(toWorld(frame, vec3(sinTheta * std::cos(phi), sinTheta * std::sin(phi), 1.f - oneMinusCos)));
    // Distance to the sphere along the sampled direction (nearest root; the centre for r = 0).
    const float b = glm::dot(d, s.direction);
    const float disc = b * b - (dist2 - r * r);
    s.distance = r > 0.f ? b - std::sqrt(std::max(disc, 0.f)) : dist;
    // pdf = 1 / (2 pi (1 - cos theta_max)).
    s.radianceOverPdf = emitted(l) * (2.f * kPi * oneMinusCosMax);
    s.pdf = 1.f / (2.f * kPi * oneMinusCosMax);
    // A zero-radius sphere is a point light of intensity 0: nothing to sample.
    s.valid = r > 0.f && std::isfinite(s.radianceOverPdf.x) && s.distance > 0.f;
    return s;
}

AreaLightHit intersectAreaLight(const ecs::LightSnapshot& l, const vec3& p, const vec3& direction) {
    AreaLightHit h;
    if (l.light.type == ecs::LightType::Rect) {
        // Step: the plane of the rectangle, then its extent in the light's axes
        // (d = a ax + b ay, solved with cross products: no orthogonality assumed).
        const vec3 ax = vec3(l.worldFromLight[0]), ay = vec3(l.worldFromLight[1]);
        const vec3 n = glm::cross(ax, ay);
        const float nn = glm::dot(n, n);
        const float denom = glm::dot(direction, n);
        if (!(nn > 0.f) || denom == 0.f) return h;
        const vec3 toCentre = lightPosition(l) - p;
        const float t = glm::dot(toCentre, n) / denom;
        if (!(t > 0.f) || !std::isfinite(t)) return h;
        const vec3 d = direction * t - toCentre;  // from the centre, in the plane
        const float a = glm::dot(glm::cross(d, ay), n) / nn / l.light.size.x;
        const float b = glm::dot(glm::cross(ax, d), n) / nn / l.light.size.y;
        if (!(std::abs(a) <= 0.5f && std::abs(b) <= 0.5f)) return h;
        // Step: the same solid-angle pdf as sampleAreaLight's.
        const float cosLight = glm::dot(-direction, lightForward(l));
        if (!(cosLight > 0.f)) return h;  // the back of a one-sided panel
        const float area = rectWorldArea(l);
        h.pdf = t * t / (cosLight * area);
        h.distance = t;
    } else if (l.light.type == ecs::LightType::Sphere) {
        // Step: the nearest root; the cone sampleAreaLight samples is exactly
        // the set of directions that meet the sphere.
        const vec3 d = lightPosition(l) - p;
        const float dist2 = glm::dot(d, d);
        const float r = std::max(l.light.radius, 0.f);
        if (!(r > 0.f) || !(dist2 > r * r)) return h;
        const float b = glm::dot(d, direction);
        const float disc = b * b - (dist2 - r * r);
        if (!(b > 0.f) || !(disc >= 0.f)) return h;
        h.pdf = 1.f / (2.f * kPi * sphereConeOneMinusCos(dist2, r));
        h.distance = b - std::sqrt(disc);
    } else {
        return h;
    }
    h.radiance = emitted(l);
    h.valid = h.distance > 0.f && std::isfinite(h.distance) && h.pdf > 0.f && std::isfinite(h.pdf);
    if (!h.valid) h = AreaLightHit{};
    return h;
}

LightSample pointLightSample(const ecs::LightSnapshot& l, const vec3& p) {
    LightSample s;
    if (l.light.type == ecs::LightType::Directional) {
        s.direction = -lightForward(l);
        s.distance = kInfinity;
        s.radianceOverPdf = emitted(l);
        s.valid = true;
        return s;
    }
    const vec3 d = lightPosition(l) - p;
    const float dist2 = glm::dot(d, d);
    if (!(dist2 > 0.f)) return s;
    const float dist = std::sqrt(dist2);
    if (l.light.range > 0.f && dist > l.light.range) return s;
    s.direction = d / dist;
    s.distance = dist;
    float falloff = 1.f;
    if (l.light.type == ecs::LightType::Spot) {
        const float cosAngle = glm::dot(-s.direction, lightForward(l));
        const float cosOuter = std::cos(l.light.outerConeAngle), cosInner = std::cos(l.light.innerConeAngle);
        falloff = glm::clamp((cosAngle - cosOuter) / std::max(cosInner - cosOuter, 1e-4f), 0.f, 1.f);
        falloff *= falloff;
    }
    s.radianceOverPdf = emitted(l) * (falloff / dist2);
    s.valid = falloff > 0.f && std::isfinite(s.radianceOverPdf.x);
    return s;
}

float pointLightImportance(const ecs::LightSnapshot& l, const ShadingPoint& sp) {
    const LightSample s = pointLightSample(l, sp.position);
    if (!s.valid) return 0.f;
    // Irradiance (cos Le / d^2, as the area lights' weights) plus pi x the
    // specular lobe's response: a glossy or grazing highlight is not picked rarely.
    const float cosI = glm::dot(sp.normal, s.direction);
    if (!(cosI > 0.f) || glm::dot(sp.geometricNormal, s.direction) <= 0.f) return 0.f;
    const float importance = luminance(s.radianceOverPdf) * (cosI + kPi * luminance(evalSpecularCos(sp, s.direction)));
    return std::isfinite(importance) ? importance : 0.f;
}

namespace {

// The specular lobe of the unshadowed estimate for a rect light: the same
// GGX D G2 F / (4 cosO) x cosI as evalSpecularCos, four samples per SIMD
// step, with everything that depends only on the surface point or the light
// hoisted out of the loop (the scalar loop was most of the shadow pass's
// time: 16 samples per pixel and light).
using V4 = simd::vfloat<4>;
RTLAB_SIMD_INLINE V4 sqrt4(const V4& v) { return __builtin_ia32_sqrtps(v); }
RTLAB_SIMD_INLINE V4 dot4(const V4* a, const vec3& b) { return a[0] * b.x + a[1] * b.y + a[2] * b.z; }

vec3 sampledRectSpecular(const ecs::LightSnapshot& light, const ShadingPoint& sp, int side, vec2 jitter) {
    // Step: the light's constants (as sampleAreaLight computes them per sample).
    const vec3 toCentre = lightPosition(light) - sp.position;
    const vec3 xAxis = vec3(light.worldFromLight[0]), yAxis = vec3(light.worldFromLight[1]);
    const vec3 ax = light.light.size.x * xAxis, ay = light.light.size.y * yAxis;
    const vec3 forward = lightForward(light);
    const float area = rectWorldArea(light);
    // Step: the surface point's constants.
    const vec3& wo = sp.woLocal;
    const float cosO = std::max(glm::dot(sp.normal, sp.wo), 1e-6f);
    const float alpha = ggxAlpha(sp.roughness);  // in [kMinGgxAlpha, 1]
    const float a2 = alpha * alpha;
    const float oz = std::fabs(wo.z);
    const float smithO = std::sqrt(wo.z * wo.z + a2 * (wo.x * wo.x + wo.y * wo.y));
    const float scale = area / (4.f * cosO * kPi * a2);
    // Step: four grid cells per step; F = f0 + (1 - f0) m^5 splits into two sums.
    const int count = side * side;
    V4 sumSpec = simd::splat<4>(0.f), sumSpecM5 = simd::splat<4>(0.f);
    const V4 zero = simd::splat<4>(0.f), one = simd::splat<4>(1.f);
    for (int first = 0; first < count; first += 4) {
        V4 su, sv, live;
        for (int lane = 0; lane < 4; ++lane) {
            const int k = std::min(first + lane, count - 1);
            su[lane] = glm::fract((float(k % side) + jitter.x) / float(side)) - 0.5f;
            sv[lane] = glm::fract((float(k / side) + jitter.y) / float(side)) - 0.5f;
            live[lane] = first + lane < count ? 1.f : 0.f;
        }
        // Step: the point on the panel, its direction and solid-angle weight.
        const V4 d[3] = {toCentre.x + su * ax.x + sv * ay.x, toCentre.y + su * ax.y + sv * ay.y,
                         toCentre.z + su * ax.z + sv * ay.z};
        const V4 dist2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        const V4 invDist = one / sqrt4(dist2);
        const V4 w[3] = {d[0] * invDist, d[1] * invDist, d[2] * invDist};
        const V4 cosLight = -dot4(w, forward);
        // Step: D, G2 and m in the shading frame (h unnormalised: |h|^2 divides out).
        const V4 wi[3] = {dot4(w, sp.frame.t), dot4(w, sp.frame.b), dot4(w, sp.frame.n)};
        const V4 h[3] = {wo.x + wi[0], wo.y + wi[1], wo.z + wi[2]};
        const V4 h2 = h[0] * h[0] + h[1] * h[1] + h[2] * h[2];
        const V4 t = (h[0] * h[0] + h[1] * h[1]) / (h2 * a2) + h[2] * h[2] / h2;
        const V4 iz = (V4)((simd::vint<4>)wi[2] & 0x7fffffff);
        const V4 smithI = sqrt4(wi[2] * wi[2] + a2 * (wi[0] * wi[0] + wi[1] * wi[1]));
        const V4 den = smithO * iz + smithI * oz;
        const V4 g2raw = 2.f * oz * iz / den;
        const V4 g2 = simd::select<4>(den > zero, simd::select<4>(g2raw < one, g2raw, one), zero);
        const V4 cosIH = (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) / sqrt4(h2);
        const V4 m = one - simd::select<4>(cosIH > zero, simd::select<4>(cosIH < one, cosIH, one), zero);
        const V4 m5 = (m * m) * (m * m) * m;
        const V4 spec = g2 / (t * t) * scale * (cosLight / dist2);
        // Step: only the cells that count: on the panel's lit side, above both hemispheres, finite.
        const auto valid = (live > zero) & (dist2 > zero) & (cosLight > zero) & (dot4(w, sp.normal) > zero) &
                           (dot4(w, sp.geometricNormal) > zero) & (h2 > zero) & (spec == spec) &
                           (spec < simd::splat<4>(kInfinity));
        sumSpec += simd::select<4>(valid, spec, zero);
        sumSpecM5 += simd::select<4>(valid, spec * m5, zero);
    }
    const float specSum = (sumSpec[0] + sumSpec[1]) + (sumSpec[2] + sumSpec[3]);
    const float specM5Sum = (sumSpecM5[0] + sumSpecM5[1]) + (sumSpecM5[2] + sumSpecM5[3]);
    const vec3 f0 = specularF0(sp);
    return (f0 * specSum + (vec3(1.f) - f0) * specM5Sum) * emitted(light) / float(count);
}

}  // namespace

void rectCorners(const ecs::LightSnapshot& light, const vec3& toCentre, vec3* corners) {
    const vec3 ax = 0.5f * light.light.size.x * vec3(light.worldFromLight[0]);
    const vec3 ay = 0.5f * light.light.size.y * vec3(light.worldFromLight[1]);
    corners[0] = toCentre - ax - ay;
    corners[1] = toCentre + ax - ay;
    corners[2] = toCentre + ax + ay;
    corners[3] = toCentre - ax + ay;
}

float polygonCosineIntegral(const vec3* corners, int count, const vec3& n, const vec3& ng) {
    // Step: clip the polygon (points relative to the surface point) to the
    // half-spaces n.q >= 0 and ng.q >= 0 (Sutherland-Hodgman; convex stays convex).
    constexpr int kMax = 12;
    vec3 a[kMax], b[kMax];
    int na = std::min(count, 8);
    for (int i = 0; i < na; ++i) a[i] = corners[i];
    const auto clip = [](const vec3* in, int m, vec3* out, const vec3& plane) {
        int k = 0;
        for (int i = 0; i < m; ++i) {
            const vec3& p = in[i];
            const vec3& q = in[(i + 1) % m];
            const float dp = glm::dot(plane, p), dq = glm::dot(plane, q);
            if (dp >= 0.f) out[k++] = p;
            if ((dp >= 0.f) != (dq >= 0.f)) out[k++] = p + (q - p) * (dp / (dp - dq));
        }
        return k;
    };
    int nb = clip(a, na, b, n);
    na = nb > 2 ? clip(b, nb, a, ng) : 0;
    if (na < 3) return 0.f;
    // Step: Lambert's formula, half the sum over edges of the angle they
    // subtend times n . (unit normal of the edge's plane); the angle as
    // atan2(|u x v|, u . v), exact for the small angles of distant lights.
    float sum = 0.f;
    for (int i = 0; i < na; ++i) {
        const vec3 u = glm::normalize(a[i]), v = glm::normalize(a[(i + 1) % na]);
        const vec3 c = glm::cross(u, v);
        const float s = glm::length(c);
        if (!(s > 0.f)) continue;  // a repeated point adds nothing
        sum += glm::dot(n, c) * (std::atan2(s, glm::dot(u, v)) / s);
    }
    const float integral = 0.5f * std::abs(sum);
    return std::isfinite(integral) ? std::min(integral, kPi) : 0.f;
}

std::optional<float> sphereCosineIntegral(const vec3& toCentre, float radius, const vec3& n, const vec3& ng) {
    const float dist2 = glm::dot(toCentre, toCentre);
    if (!(dist2 > radius * radius)) return 0.f;  // inside the light: nothing (as its sampler)
    const float dist = std::sqrt(dist2);
    const float sinSigma2 = radius * radius / dist2;
    const float sinSigma = std::sqrt(sinSigma2);
    const float cosTheta = glm::clamp(glm::dot(n, toCentre) / dist, -1.f, 1.f);
    const bool sameHemispheres = n == ng;
    // Step: a cap cut by the geometric horizon too is left to sampling.
    if (!sameHemispheres && glm::dot(ng, toCentre) / dist < sinSigma) return std::nullopt;
    if (cosTheta >= sinSigma) return kPi * sinSigma2 * cosTheta;  // the whole cap above the horizon
    if (cosTheta <= -sinSigma) return 0.f;                        // the whole cap below it
    // Step: the cap cut by the horizon (Snyder 1996): with x = cot(sigma),
    // y = -x cot(theta), z = sin(theta) sqrt(1 - y^2),
    //   integral = (cos(theta) acos(y) - x z) sin^2(sigma) + atan(z / x).
    const float sinTheta = std::sqrt(std::max(0.f, 1.f - cosTheta * cosTheta));
    const float x = std::sqrt(std::max(0.f, 1.f - sinSigma2)) / sinSigma;
    const float y = glm::clamp(-x * cosTheta / std::max(sinTheta, 1e-30f), -1.f, 1.f);
    const float z = sinTheta * std::sqrt(std::max(0.f, 1.f - y * y));
    const float integral = (cosTheta * std::acos(y) - x * z) * sinSigma2 + std::atan2(z, x);
    return std::isfinite(integral) ? glm::clamp(integral, 0.f, kPi * sinSigma2) : 0.f;
}

vec3 unshadowedAreaLight(const ecs::LightSnapshot& light, const ShadingPoint& sp, int samples, const SampleKey& key,
                         std::uint32_t dimension) {
    // Step: the diffuse term in closed form (the light's uniform radiance x
    // the integral of cos over the part of it above both hemispheres).
    std::optional<float> cosineIntegral;
    if (light.light.type == ecs::LightType::Rect) {
        const vec3 toCentre = lightPosition(light) - sp.position;
        if (!(glm::dot(toCentre, lightForward(light)) < 0.f)) return vec3(0.f);  // behind the one-sided panel
        vec3 corners[4];
        rectCorners(light, toCentre, corners);
        cosineIntegral = polygonCosineIntegral(corners, 4, sp.normal, sp.geometricNormal);
    } else {
        cosineIntegral = sphereCosineIntegral(lightPosition(light) - sp.position, std::max(light.light.radius, 0.f),
                                              sp.normal, sp.geometricNormal);
    }
    vec3 sum(0.f);
    const vec3 diffuse = (1.f - sp.metalness) * (1.f - sp.transmission) * sp.albedo / kPi;
    if (cosineIntegral) sum = diffuse * emitted(light) * *cosineIntegral;
    // Step: the rest (the specular lobe; the diffuse one where no closed form
    // applies) by stratified samples on a sqrt(n) x sqrt(n) grid, jittered by the pixel's hash.
    const bool specular = glm::dot(sp.normal, sp.wo) > 0.f;  // evalSpecularCos is 0 otherwise
    if (cosineIntegral && !specular) return sum;
    const int side = std::max(1, static_cast<int>(std::sqrt(static_cast<float>(samples))));
    const vec2 jitter(sampleUniform(key, dimension), sampleUniform(key, dimension + 1));
    if (cosineIntegral && light.light.type == ecs::LightType::Rect)
        return sum + sampledRectSpecular(light, sp, side, jitter);
    vec3 sampled(0.f);
    for (int j = 0; j < side; ++j)
        for (int i = 0; i < side; ++i) {
            const vec2 u = glm::fract((vec2(i, j) + jitter) / float(side));
            const LightSample s = sampleAreaLight(light, sp.position, u);
            if (!s.valid) continue;
            const vec3 f = cosineIntegral ? evalSpecularCos(sp, s.direction) : evalBrdfCos(sp, s.direction);
            sampled += f * s.radianceOverPdf;
        }
    return sum + sampled / float(side * side);
}

bool emits(const ecs::LightSnapshot& l) {
    return l.light.intensity > 0.f && glm::length(l.light.color) > 0.f && std::isfinite(l.light.intensity);
}

float lightPickWeight(const ecs::LightSnapshot& l, const ShadingPoint& sp) {
    if (!emits(l)) return 0.f;
    if (!l.light.isArea()) return pointLightImportance(l, sp);
    // Area lights: intensity x area / distance^2, zero only when the whole
    // light is below the surface (any rect corner / the sphere's top above
    // it) or the point is behind a one-sided panel.
    const vec3 d = lightPosition(l) - sp.position;
    const float dist2 = std::max(glm::dot(d, d), 1e-8f);
    bool above = false;
    if (l.light.type == ecs::LightType::Rect) {
        vec3 corners[4];
        rectCorners(l, d, corners);
        for (int c = 0; c < 4 && !above; ++c) above = glm::dot(sp.normal, corners[c]) > 0.f;
        above = above && glm::dot(d, lightForward(l)) < 0.f;
    } else {
        above = glm::dot(sp.normal, d) > -l.light.radius;
    }
    const float area = l.light.type == ecs::LightType::Rect ? rectWorldArea(l) : lightArea(l);
    return above ? luminance(emitted(l)) * area / dist2 : 0.f;
}

const ecs::LightSnapshot* pickLight(const ecs::SceneSnapshot& scene, const ShadingPoint& sp, float u, float& pdf) {
    return pickByWeight(
        scene.lights, [&](const ecs::LightSnapshot& l) { return lightPickWeight(l, sp); }, u, pdf,
        kDefensiveLightPickShare);
}

float lightPickPdf(const ecs::SceneSnapshot& scene, const ShadingPoint& sp, const ecs::LightSnapshot& light) {
    return pickPdfByWeight(
        scene.lights, [&](const ecs::LightSnapshot& l) { return lightPickWeight(l, sp); }, light,
        kDefensiveLightPickShare);
}

}  // namespace rtlab::shaders::detail
