#include "render_context.hpp"

#include <rtlab/core/parallel.hpp>
#include <rtlab/shaders_cpp/sampling.hpp>

#include <algorithm>
#include <memory>
#include <type_traits>

namespace rtlab::shaders::detail {
namespace {

// Closest-hit of radiance-like rays: the surface at the hit.
void surfaceClosestHit(const RenderContext& ctx, const tracer::HitContext& hc, HitPayload& p,
                       const tracer::HitAttributes& attr) {
    const SurfacePoint sp =
        surfacePoint(ctx.scene, ctx.accel.instanceFacts(hc.instanceIndex).normalFromObject, hc, attr);
    const ecs::Geometry& g = (*ctx.scene.meshes)[hc.instance->mesh].geometries[hc.geometryIndex];
    p.hit = true;
    p.t = hc.rayTCurrent;
    p.instance = hc.instanceIndex;
    p.mesh = hc.instance->mesh;
    p.entity = hc.instance->entity.index;
    p.geometry = hc.geometryIndex;
    p.primitive = hc.primitiveIndex;
    p.barycentrics = attr.barycentrics();
    p.position = sp.position;
    p.frontFace = glm::dot(sp.geometricNormal, hc.worldRayDirection) < 0.f;
    p.geometricNormal = p.frontFace ? sp.geometricNormal : -sp.geometricNormal;
    p.shadingNormal = p.frontFace ? sp.shadingNormal : -sp.shadingNormal;
    // A shading normal on the far side of the geometric one would leak light: bend it back.
    if (glm::dot(p.shadingNormal, p.geometricNormal) <= 0.f) p.shadingNormal = p.geometricNormal;
    p.uv = sp.uv;
    p.material = g.material;
    p.albedo = vec3(baseColorAt(ctx.material(g.material), *ctx.scene.textures, sp));
    p.errorScale = errorScaleOf(sp.position, hc.worldRayOrigin);
}

}  // namespace

RenderContext::RenderContext(const tracer::AccelManager& accel_, const ecs::SceneSnapshot& scene_,
                             const FramePlan& plan_, const RenderSettings& settings_)
    : accel(accel_), scene(scene_), plan(plan_), settings(settings_), width(settings_.width), height(settings_.height),
      gbuffer(vectorTouchedInParallel<GPixel>(std::size_t(settings_.width) * std::size_t(settings_.height))) {
    if (plan.has(Pass::Volumes)) media = mediaOf(scene);
    // Step: the shader table — one record per (geometry slot, ray type).
    RtPipeline::Desc desc;
    desc.rayTypeCount = kRayTypeCount;
    const bool alpha = plan.has(Pass::AlphaMask);
    const auto closest = [this](const tracer::HitContext& hc, HitPayload& p, const tracer::HitAttributes& a) {
        surfaceClosestHit(*this, hc, p, a);
    };
    const auto distanceOnly = [](const tracer::HitContext& hc, HitPayload& p, const tracer::HitAttributes&) {
        p.hit = true;
        p.t = hc.rayTCurrent;
    };
    const auto alphaTest = [this](const tracer::HitContext& hc, HitPayload&, const tracer::HitAttributes& attr) {
        const ecs::Geometry& g = (*scene.meshes)[hc.instance->mesh].geometries[hc.geometryIndex];
        const ecs::Material& m = material(g.material);
        const SurfacePoint sp = surfacePoint(scene, accel.instanceFacts(hc.instanceIndex).normalFromObject, hc, attr);
        return baseColorAt(m, *scene.textures, sp).a < m.alphaCutoff ? tracer::AnyHitResult::Ignore
                                                                     : tracer::AnyHitResult::Accept;
    };
    desc.hitGroups = tracer::buildMaterialShaderTable<HitPayload>(
        accel, scene, kRayTypeCount, [&](const ecs::Material& m, const ecs::Geometry&, std::uint32_t rayType) {
            RtPipeline::HitGroup group;
            if (rayType == kRayShadow || rayType == kRayOcclusion) group.closestHit = distanceOnly;
            else group.closestHit = closest;
            // Any-hit only where the plan has the alpha pass and the material is masked.
            if (alpha && m.alphaMode == ecs::AlphaMode::Mask) group.anyHit = alphaTest;
            return group;
        });
    desc.missShaders.push_back([](const tracer::MissContext&, HitPayload& p) {
        p.hit = false;
        p.missed = true;
    });
    desc.maxRecursionDepth = 1;
    pipeline_ = std::make_unique<RtPipeline>(accel, std::move(desc), settings.backend);
}

tracer::TraceArgs RenderContext::args(RayType type, std::uint32_t extraFlags) const {
    tracer::TraceArgs a;
    a.rayContribution = type;
    a.multiplier = kRayTypeCount;
    a.rayFlags = extraFlags;
    if (!plan.has(Pass::AlphaMask)) a.rayFlags |= tracer::RayFlag::ForceOpaque;
    return a;
}

const ecs::Material& RenderContext::material(std::uint32_t id) const {
    static const ecs::Material kDefault{};
    return id < scene.materials->size() ? (*scene.materials)[id] : kDefault;
}

vec3 rayOriginLeaving(const vec3& position, const vec3& geometricNormal, const vec3& direction, float errorScale) {
    return offsetRayOriginByError(
        position, glm::dot(direction, geometricNormal) >= 0.f ? geometricNormal : -geometricNormal, errorScale);
}

vec3 cosineDirectionAbove(const vec3& n, const vec3& ng, vec2 u) {
    vec3 dir = glm::normalize(toWorld(makeFrame(n), sampleCosineHemisphere(u)));
    if (glm::dot(dir, ng) <= 0.f) dir = glm::normalize(dir - 2.f * glm::dot(dir, ng) * ng);
    return dir;
}

float errorScaleOf(const vec3& a, const vec3& b) {
    const vec3 m = glm::max(glm::abs(a), glm::abs(b));
    return std::max({m.x, m.y, m.z});
}

}  // namespace rtlab::shaders::detail
