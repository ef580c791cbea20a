#pragma once
// Preview shading: primary rays only, traced as 8-wide Embree packets over
// fixed tiles; shades albedo x (ambient + view-facing term) and writes the
// guide AOVs (albedo, world normal, view depth). This is the renderer until
// the effect shaders land; its output is deterministic for any thread count.
#include <rtlab/core/image.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <cstdint>

namespace rtlab::shaders {

struct PreviewSettings {
    int width = 640;
    int height = 360;
};

struct PreviewResult {
    Image image;  // R,G,B beauty; albedo.R/G/B; normal.R/G/B (world); depth.Z (view z, 0 on miss)
    std::uint64_t primaryRays = 0;
    std::uint64_t hits = 0;
    std::uint64_t misses = 0;
};

PreviewResult renderPreview(const tracer::AccelManager& accel, const ecs::SceneSnapshot& scene,
                            const PreviewSettings& settings);

// Camera ray through the centre of pixel (x, y) (top row y = 0).
struct CameraRay {
    vec3 origin;
    vec3 direction;  // unit length
};
CameraRay cameraRay(const ecs::CameraSnapshot& camera, int width, int height, float px, float py);

// Base colour of a material at a surface UV (texture sampled nearest, sRGB decoded).
vec4 baseColorAt(const ecs::Material& material, const std::vector<ecs::Texture>& textures, const vec2& uv);

}  // namespace rtlab::shaders
