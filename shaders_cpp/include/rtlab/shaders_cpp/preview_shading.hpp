#pragma once
// Preview shading: primary rays only, through the DXR pipeline's coherent
// 8-wide packet path; alpha-masked materials run an any-hit alpha test.
// Shades albedo x (ambient + view-facing term) and writes the guide AOVs
// (albedo, world normal, view depth). This is the renderer until the effect
// shaders land; its output is deterministic for any thread count.
#include <rtlab/core/image.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <cstdint>
#include <optional>
#include <vector>

namespace rtlab::shaders {

struct PreviewSettings {
    int width = 640;
    int height = 360;
    // Traversal back end (not owned); nullptr = Embree. See tracer::TraversalBackend.
    tracer::TraversalBackend* backend = nullptr;
    // Fill PreviewResult::primaryRayPixels (which pixel each primary ray
    // belongs to, in the order of the back end's primary-ray records).
    bool recordRayOrder = false;
};

struct PreviewResult {
    Image image;  // R,G,B beauty; albedo.R/G/B; normal.R/G/B (world); depth.Z (view z, 0 on miss)
    std::uint64_t primaryRays = 0;
    std::uint64_t hits = 0;
    std::uint64_t misses = 0;
    tracer::TraceCounters counters;
    // With PreviewSettings::recordRayOrder: pixel index (y * width + x) of
    // every primary ray in the dispatch's thread order (tilePixelOrder), the
    // order of the RT-core model's primary-ray records.
    std::vector<std::uint32_t> primaryRayPixels;
};

PreviewResult renderPreview(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene,
                            const PreviewSettings& settings);

// Camera ray through the centre of pixel (x, y) (top row y = 0).
struct CameraRay {
    vec3 origin;
    vec3 direction;  // unit length
};
// A pinhole camera for one image size, with what every pixel needs (tan of
// half the field of view, the rotation, the inverse transform) computed once:
// per-pixel callers construct it outside their loop.
class PinholeCamera {
public:
    PinholeCamera(const ecs::CameraSnapshot& camera, int width, int height);
    // The ray through continuous pixel position (px, py).
    CameraRay ray(float px, float py) const;
    // The inverse of ray(): the continuous pixel position of a world point, or
    // nothing when it lies behind the camera.
    std::optional<vec2> project(const vec3& worldPoint) const;

private:
    vec3 origin_;
    mat3 rotation_;  // camera -> world
    mat4 cameraFromWorld_;
    float tanHalf_, aspect_;
    float width_, height_;
};
// One-off forms of the above.
CameraRay cameraRay(const ecs::CameraSnapshot& camera, int width, int height, float px, float py);
std::optional<vec2> projectToPixel(const ecs::CameraSnapshot& camera, int width, int height, const vec3& worldPoint);

// Surface attributes at a committed triangle hit, in world space.
struct SurfacePoint {
    vec3 position{0.f};
    vec3 geometricNormal{0.f, 0.f, 1.f};
    vec3 shadingNormal{0.f, 0.f, 1.f};  // interpolated vertex normal (unit)
    vec2 uv{0.f};
    vec4 color{1.f};  // interpolated vertex colour (white where the geometry has none)
};
// normalFromObject: the instance's inverse-transpose 3x3 (AccelManager::instanceFacts).
SurfacePoint surfacePoint(const ecs::SceneSnapshot& scene, const mat3& normalFromObject, const tracer::HitContext& ctx,
                          const tracer::HitAttributes& attr);

// Base colour of a material at a surface UV (texture sampled nearest, sRGB decoded).
vec4 baseColorAt(const ecs::Material& material, const std::vector<ecs::Texture>& textures, const vec2& uv);
// Base colour at a surface point: the material's at its UV times its vertex colour.
inline vec4 baseColorAt(const ecs::Material& material, const std::vector<ecs::Texture>& textures,
                        const SurfacePoint& sp) {
    return baseColorAt(material, textures, sp.uv) * sp.color;
}

}  // namespace rtlab::shaders
