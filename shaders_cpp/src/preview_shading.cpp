#include <rtlab/core/parallel.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>

#include <rtlab/tracer/pipeline.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

namespace rtlab::shaders {
namespace {

struct PreviewPayload {
    vec3 color{0.f};
    vec3 albedo{0.f};
    vec3 normal{0.f};
    float depth = 0.f;
};

float srgb8ToLinear(std::uint8_t v) { return srgbToLinear(v / 255.f); }

}  // namespace

PinholeCamera::PinholeCamera(const ecs::CameraSnapshot& camera, int width, int height)
    : origin_(vec3(camera.worldFromCamera[3])), rotation_(mat3(camera.worldFromCamera)),
      cameraFromWorld_(glm::inverse(camera.worldFromCamera)), tanHalf_(std::tan(0.5f * camera.camera.yfov)),
      aspect_(camera.camera.aspectRatio > 0.f ? camera.camera.aspectRatio
                                              : static_cast<float>(width) / static_cast<float>(height)),
      width_(static_cast<float>(width)), height_(static_cast<float>(height)) {}

CameraRay PinholeCamera::ray(float px, float py) const {
    const float sx = (2.f * px / width_ - 1.f) * tanHalf_ * aspect_;
    const float sy = (1.f - 2.f * py / height_) * tanHalf_;
    const vec3 dirCamera = glm::normalize(vec3(sx, sy, -1.f));
    return {origin_, glm::normalize(rotation_ * dirCamera)};
}

std::optional<vec2> PinholeCamera::project(const vec3& worldPoint) const {
    const vec3 p = vec3(cameraFromWorld_ * vec4(worldPoint, 1.f));
    if (!(p.z < 0.f)) return std::nullopt;
    const float sx = p.x / -p.z, sy = p.y / -p.z;
    return vec2((sx / (tanHalf_ * aspect_) + 1.f) * 0.5f * width_, (1.f - sy / tanHalf_) * 0.5f * height_);
}

CameraRay cameraRay(const ecs::CameraSnapshot& camera, int width, int height, float px, float py) {
    return PinholeCamera(camera, width, height).ray(px, py);
}

std::optional<vec2> projectToPixel(const ecs::CameraSnapshot& camera, int width, int height, const vec3& worldPoint) {
    return PinholeCamera(camera, width, height).project(worldPoint);
}

vec4 baseColorAt(const ecs::Material& material, const std::vector<ecs::Texture>& textures, const vec2& uv) {
    vec4 c = material.baseColor;
    if (material.baseColorTexture < textures.size()) {
        const ecs::Texture& t = textures[material.baseColorTexture];
        if (t.width > 0 && t.height > 0) {
            // Nearest texel with wrap-around (glTF default REPEAT).
            const float fu = uv.x - std::floor(uv.x), fv = uv.y - std::floor(uv.y);
            const int x = std::clamp(static_cast<int>(fu * t.width), 0, t.width - 1);
            const int y = std::clamp(static_cast<int>(fv * t.height), 0, t.height - 1);
            const std::uint8_t* px = &t.rgba8[(static_cast<std::size_t>(y) * t.width + x) * 4];
            const vec3 rgb = t.srgb ? vec3(srgb8ToLinear(px[0]), srgb8ToLinear(px[1]), srgb8ToLinear(px[2]))
                                    : vec3(px[0], px[1], px[2]) / 255.f;
            c *= vec4(rgb, px[3] / 255.f);
        }
    }
    return c;
}

PreviewResult renderPreview(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene,
                            const PreviewSettings& settings) {
    const int w = settings.width, h = settings.height;
    std::vector<vec3> beauty(static_cast<std::size_t>(w) * h), albedo(beauty.size()), normal(beauty.size());
    std::vector<float> depth(beauty.size(), 0.f);
    const vec3 cameraForward = -glm::normalize(vec3(scene.camera.worldFromCamera[2]));
    const auto& materials = *scene.materials;
    const auto& textures = *scene.textures;

    // Step: shader table — one hit group per geometry slot (one ray type).
    // Alpha-masked materials get an any-hit shader that ignores cut-out texels.
    using Pipeline = tracer::Pipeline<PreviewPayload>;
    Pipeline::Desc desc;
    const auto materialOf = [&](const tracer::HitContext& ctx) -> const ecs::Material& {
        const ecs::Geometry& g = (*scene.meshes)[ctx.instance->mesh].geometries[ctx.geometryIndex];
        return materials[g.material < materials.size() ? g.material : 0];
    };
    const auto closestHit = [&](const tracer::HitContext& ctx, PreviewPayload& p, const tracer::HitAttributes& attr) {
        const SurfacePoint sp = surfacePoint(scene, accel.instanceFacts(ctx.instanceIndex).normalFromObject, ctx, attr);
        const ecs::Material& m = materialOf(ctx);
        vec3 n = sp.shadingNormal;
        if (glm::dot(n, ctx.worldRayDirection) > 0.f) n = -n;  // face the viewer
        p.albedo = vec3(baseColorAt(m, textures, sp));
        p.normal = n;
        p.depth = ctx.rayTCurrent * glm::dot(ctx.worldRayDirection, cameraForward);
        p.color = p.albedo * (0.2f + 0.8f * std::abs(glm::dot(n, ctx.worldRayDirection))) + m.emissive;
    };
    const auto alphaTest = [&](const tracer::HitContext& ctx, PreviewPayload&, const tracer::HitAttributes& attr) {
        const ecs::Material& m = materialOf(ctx);
        const SurfacePoint sp = surfacePoint(scene, accel.instanceFacts(ctx.instanceIndex).normalFromObject, ctx, attr);
        return baseColorAt(m, textures, sp).a < m.alphaCutoff ? tracer::AnyHitResult::Ignore
                                                              : tracer::AnyHitResult::Accept;
    };
    desc.hitGroups = tracer::buildMaterialShaderTable<PreviewPayload>(
        accel, scene, 1, [&](const ecs::Material& material, const ecs::Geometry&, std::uint32_t) {
            Pipeline::HitGroup group;
            group.closestHit = closestHit;
            if (material.alphaMode == ecs::AlphaMode::Mask) group.anyHit = alphaTest;
            return group;
        });
    desc.missShaders.push_back([](const tracer::MissContext&, PreviewPayload& p) { p = PreviewPayload{}; });
    const Pipeline pipeline(accel, std::move(desc), settings.backend);

    // Step: coherent primary rays through 8-wide packets.
    if (settings.recordRayOrder && !settings.backend)
        throw std::invalid_argument("renderPreview: recordRayOrder needs a back end");
    const PinholeCamera camera(scene.camera, w, h);
    const tracer::TraceCounters counters = pipeline.dispatchCoherent(
        w, h, tracer::TraceArgs{},
        [&](int x, int y, PreviewPayload&) {
            const CameraRay ray = camera.ray(x + 0.5f, y + 0.5f);
            return tracer::RayDesc{ray.origin, 0.f, ray.direction, kInfinity};
        },
        [&](int x, int y, const PreviewPayload& p) {
            const std::size_t pixel = static_cast<std::size_t>(y) * w + x;
            beauty[pixel] = p.color;
            albedo[pixel] = p.albedo;
            normal[pixel] = p.normal;
            depth[pixel] = p.depth;
        });

    PreviewResult result;
    result.image = Image(w, h);
    result.image.addRgbLayer("", beauty);
    result.image.addRgbLayer("albedo", albedo);
    result.image.addRgbLayer("normal", normal);
    float* z = result.image.addChannel("depth.Z");
    std::copy(depth.begin(), depth.end(), z);
    result.counters = counters;
    if (settings.recordRayOrder) result.primaryRayPixels = tilePixelOrder(w, h);
    result.primaryRays = counters.rays[0];
    result.hits = counters.hits[0];
    result.misses = counters.misses[0];
    return result;
}

SurfacePoint surfacePoint(const ecs::SceneSnapshot& scene, const mat3& normalFromObject, const tracer::HitContext& ctx,
                          const tracer::HitAttributes& attr) {
    const ecs::Geometry& g = (*scene.meshes)[ctx.instance->mesh].geometries[ctx.geometryIndex];
    SurfacePoint sp;
    sp.position = ctx.worldHitPosition();
    if (g.procedural()) {
        sp.shadingNormal = sp.geometricNormal = -ctx.worldRayDirection;
        return sp;
    }
    const vec2 b = attr.barycentrics();
    const std::uint32_t i0 = g.indices[3 * ctx.primitiveIndex], i1 = g.indices[3 * ctx.primitiveIndex + 1],
                        i2 = g.indices[3 * ctx.primitiveIndex + 2];
    const float w0 = 1.f - b.x - b.y;
    // Normals go to world space with the inverse transpose of worldFromObject (cached per instance).
    const auto toWorld = [&](const vec3& n) {
        const vec3 v = normalFromObject * n;
        const float len = glm::length(v);
        return len > 0.f && std::isfinite(len) ? v / len : -ctx.worldRayDirection;
    };
    sp.geometricNormal = toWorld(glm::cross(g.positions[i1] - g.positions[i0], g.positions[i2] - g.positions[i0]));
    sp.shadingNormal = g.normals.size() == g.positions.size()
                           ? toWorld(w0 * g.normals[i0] + b.x * g.normals[i1] + b.y * g.normals[i2])
                           : sp.geometricNormal;
    if (g.uv0.size() == g.positions.size()) sp.uv = w0 * g.uv0[i0] + b.x * g.uv0[i1] + b.y * g.uv0[i2];
    if (g.colors.size() == g.positions.size()) sp.color = w0 * g.colors[i0] + b.x * g.colors[i1] + b.y * g.colors[i2];
    return sp;
}

}  // namespace rtlab::shaders
