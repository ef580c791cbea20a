#include "lighting.hpp"

#include <algorithm>
#include <cmath>

namespace rtlab::shaders::detail {
namespace {

vec3 lightPosition(const ecs::LightSnapshot& l) { return vec3(l.worldFromLight[3]); }
vec3 lightForward(const ecs::LightSnapshot& l) { return -glm::normalize(vec3(l.worldFromLight[2])); }
vec3 emitted(const ecs::LightSnapshot& l) { return l.light.color * l.light.intensity; }

float lightArea(const ecs::LightSnapshot& l) {
    if (l.light.type == ecs::LightType::Rect) return std::abs(l.light.size.x * l.light.size.y);
    return 4.f * kPi * l.light.radius * l.light.radius;
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

vec3 specularF0(const ShadingPoint& sp) { return glm::mix(vec3(0.04f), sp.albedo, sp.metalness); }

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

vec3 evalBrdfCos(const ShadingPoint& sp, const vec3& wi) {
    const float cosI = glm::dot(sp.normal, wi);
    const float cosO = glm::dot(sp.normal, sp.wo);
    if (!(cosI > 0.f) || glm::dot(sp.geometricNormal, wi) <= 0.f) return vec3(0.f);
    vec3 f = evalDiffuseCos(sp, wi);
    if (cosO > 0.f) {
        // Step: GGX specular D G F / (4 cosI cosO) x cosI, in the shading frame.
        const vec3& wo = sp.woLocal;
        const vec3 wiLocal = toLocal(sp.frame, wi);
        const vec3 h = glm::normalize(wo + wiLocal);
        const float alpha = ggxAlpha(sp.roughness);
        const vec3 F = fresnelSchlick(specularF0(sp), glm::dot(wiLocal, h));
        const float spec = ggxD(h, alpha) * ggxG2(wo, wiLocal, alpha) / (4.f * std::max(cosO, 1e-6f));
        if (std::isfinite(spec)) f += F * spec;
    }
    return f;
}

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
        const float area = lightArea(l) * glm::length(glm::cross(ax, ay));
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
    const float sinMax2 = r * r / dist2;
    const float cosMax = std::sqrt(std::max(0.f, 1.f - sinMax2));
    const float oneMinusCosMax = sinMax2 / (1.f + cosMax);
    const float oneMinusCos = std::min(u.x, kOneMinusEpsilon) * oneMinusCosMax;
    const float sinTheta = std::sqrt(std::max(0.f, oneMinusCos * (2.f - oneMinusCos)));
    const float phi = 2.f * kPi * u.y;
    const Frame frame = makeFrame(d / dist);
    s.direction = glm::normalize(
        toWorld(frame, vec3(sinTheta * std::cos(phi), sinTheta * std::sin(phi), 1.f - oneMinusCos)));
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
        const float area = lightArea(l) * std::sqrt(nn);
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
        const float sinMax2 = r * r / dist2;
        const float cosMax = std::sqrt(std::max(0.f, 1.f - sinMax2));
        h.pdf = 1.f / (2.f * kPi * (sinMax2 / (1.f + cosMax)));
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
    const float cosI = glm::dot(sp.normal, s.direction);
    if (!(cosI > 0.f) || glm::dot(sp.geometricNormal, s.direction) <= 0.f) return 0.f;
    return luminance(s.radianceOverPdf) * cosI;
}

vec3 unshadowedAreaLight(const ecs::LightSnapshot& light, const ShadingPoint& sp, int samples, const SampleKey& key,
                         std::uint32_t dimension) {
    // Step: stratified samples on a sqrt(n) x sqrt(n) grid, jittered by the pixel's hash.
    const int side = std::max(1, static_cast<int>(std::sqrt(static_cast<float>(samples))));
    const vec2 jitter(sampleUniform(key, dimension), sampleUniform(key, dimension + 1));
    vec3 sum(0.f);
    for (int j = 0; j < side; ++j)
        for (int i = 0; i < side; ++i) {
            const vec2 u = glm::fract((vec2(i, j) + jitter) / float(side));
            const LightSample s = sampleAreaLight(light, sp.position, u);
            if (s.valid) sum += evalBrdfCos(sp, s.direction) * s.radianceOverPdf;
        }
    return sum / float(side * side);
}

bool emits(const ecs::LightSnapshot& l) {
    return l.light.intensity > 0.f && glm::length(l.light.color) > 0.f && std::isfinite(l.light.intensity);
}

const ecs::LightSnapshot* pickLight(const ecs::SceneSnapshot& scene, const ShadingPoint& sp, float u, float& pdf) {
    return pickByWeight(
        scene.lights,
        [&](const ecs::LightSnapshot& l) -> float {
            if (!emits(l)) return 0.f;
            if (!l.light.isArea()) return pointLightImportance(l, sp);
            // Area lights: intensity x area / distance^2, zero only when the
            // whole light is below the surface (any rect corner / the sphere's top above it).
            const vec3 d = lightPosition(l) - sp.position;
            const float dist2 = std::max(glm::dot(d, d), 1e-8f);
            bool above = false;
            if (l.light.type == ecs::LightType::Rect) {
                const vec3 ax = 0.5f * l.light.size.x * vec3(l.worldFromLight[0]);
                const vec3 ay = 0.5f * l.light.size.y * vec3(l.worldFromLight[1]);
                for (int c = 0; c < 4 && !above; ++c)
                    above = glm::dot(sp.normal, d + (c & 1 ? ax : -ax) + (c & 2 ? ay : -ay)) > 0.f;
            } else {
                above = glm::dot(sp.normal, d) > -l.light.radius;
            }
            return above ? luminance(emitted(l)) * lightArea(l) / dist2 : 0.f;
        },
        u, pdf);
}

}  // namespace rtlab::shaders::detail
