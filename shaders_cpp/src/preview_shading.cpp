#include <rtlab/core/parallel.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>

#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace rtlab::shaders {
namespace {

constexpr int kPacketWidth = 8;
constexpr int kTileSize = 16;

float srgbToLinear(std::uint8_t v) {
    const float c = v / 255.f;
    return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

struct TileCounters {
    std::uint64_t rays = 0, hits = 0;
};

}  // namespace

CameraRay cameraRay(const ecs::CameraSnapshot& camera, int width, int height, float px, float py) {
    const float aspect = camera.camera.aspectRatio > 0.f ? camera.camera.aspectRatio
                                                         : static_cast<float>(width) / static_cast<float>(height);
    const float tanHalf = std::tan(0.5f * camera.camera.yfov);
    const float sx = (2.f * px / width - 1.f) * tanHalf * aspect;
    const float sy = (1.f - 2.f * py / height) * tanHalf;
    const vec3 dirCamera = glm::normalize(vec3(sx, sy, -1.f));
    return {vec3(camera.worldFromCamera[3]), glm::normalize(mat3(camera.worldFromCamera) * dirCamera)};
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
            const vec3 rgb = t.srgb ? vec3(srgbToLinear(px[0]), srgbToLinear(px[1]), srgbToLinear(px[2]))
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
    const std::vector<Tile> tiles = makeTiles(w, h, kTileSize);
    std::vector<TileCounters> counters(tiles.size());
    const vec3 cameraForward = -glm::normalize(vec3(scene.camera.worldFromCamera[2]));

    parallelForEach(tiles.size(), [&](std::size_t tileIndex) {
        const Tile& tile = tiles[tileIndex];
        RTCIntersectContext context;
        for (int y = tile.y0; y < tile.y1; ++y)
            for (int x0 = tile.x0; x0 < tile.x1; x0 += kPacketWidth) {
                // Step: fill an 8-wide SoA packet; lanes past the tile edge are masked off.
                alignas(32) std::array<int, kPacketWidth> valid{};
                alignas(32) RTCRayHit8 packet{};
                for (int lane = 0; lane < kPacketWidth; ++lane) {
                    const int x = x0 + lane;
                    valid[lane] = x < tile.x1 ? -1 : 0;
                    const CameraRay ray = cameraRay(scene.camera, w, h, x + 0.5f, y + 0.5f);
                    packet.ray.org_x[lane] = ray.origin.x;
                    packet.ray.org_y[lane] = ray.origin.y;
                    packet.ray.org_z[lane] = ray.origin.z;
                    packet.ray.dir_x[lane] = ray.direction.x;
                    packet.ray.dir_y[lane] = ray.direction.y;
                    packet.ray.dir_z[lane] = ray.direction.z;
                    packet.ray.tnear[lane] = 0.f;
                    packet.ray.tfar[lane] = kInfinity;
                    packet.ray.mask[lane] = ~0u;
                    packet.ray.flags[lane] = 0;
                    packet.ray.time[lane] = 0.f;
                    packet.hit.geomID[lane] = RTC_INVALID_GEOMETRY_ID;
                    packet.hit.instID[0][lane] = RTC_INVALID_GEOMETRY_ID;
                }
                rtcInitIntersectContext(&context);
                rtcIntersect8(valid.data(), accel.tlas(), &context, &packet);

                // Step: shade each active lane.
                for (int lane = 0; lane < kPacketWidth; ++lane) {
                    if (!valid[lane]) continue;
                    const std::size_t pixel = static_cast<std::size_t>(y) * w + x0 + lane;
                    ++counters[tileIndex].rays;
                    const vec3 dir(packet.ray.dir_x[lane], packet.ray.dir_y[lane], packet.ray.dir_z[lane]);
                    if (packet.hit.geomID[lane] == RTC_INVALID_GEOMETRY_ID) continue;  // black background
                    ++counters[tileIndex].hits;
                    const ecs::InstanceSnapshot& inst = accel.instance(packet.hit.instID[0][lane]);
                    const ecs::Geometry& g = (*scene.meshes)[inst.mesh].geometries[packet.hit.geomID[lane]];
                    const std::uint32_t prim = packet.hit.primID[lane];
                    const float u = packet.hit.u[lane], v = packet.hit.v[lane];
                    const std::uint32_t i0 = g.indices[3 * prim], i1 = g.indices[3 * prim + 1], i2 = g.indices[3 * prim + 2];
                    // Shading normal in object space, to world with the inverse transpose.
                    vec3 nObject = (1.f - u - v) * g.normals[i0] + u * g.normals[i1] + v * g.normals[i2];
                    const mat3 normalFromObject = glm::transpose(glm::inverse(mat3(inst.worldFromObject)));
                    vec3 n = normalFromObject * nObject;
                    const float len = glm::length(n);
                    n = len > 0.f && std::isfinite(len) ? n / len : -dir;
                    if (glm::dot(n, dir) > 0.f) n = -n;  // face the viewer
                    vec2 uv(0.f);
                    if (!g.uv0.empty()) uv = (1.f - u - v) * g.uv0[i0] + u * g.uv0[i1] + v * g.uv0[i2];
                    const ecs::Material& m = (*scene.materials)[g.material < scene.materials->size() ? g.material : 0];
                    const vec3 a = vec3(baseColorAt(m, *scene.textures, uv));
                    albedo[pixel] = a;
                    normal[pixel] = n;
                    const float t = packet.ray.tfar[lane];
                    depth[pixel] = t * glm::dot(dir, cameraForward);
                    beauty[pixel] = a * (0.2f + 0.8f * std::abs(glm::dot(n, dir))) + m.emissive;
                }
            }
    });

    PreviewResult result;
    result.image = Image(w, h);
    result.image.addRgbLayer("", beauty);
    result.image.addRgbLayer("albedo", albedo);
    result.image.addRgbLayer("normal", normal);
    float* z = result.image.addChannel("depth.Z");
    std::copy(depth.begin(), depth.end(), z);
    // Fixed-order reduction over tiles.
    for (const TileCounters& c : counters) {
        result.primaryRays += c.rays;
        result.hits += c.hits;
    }
    result.misses = result.primaryRays - result.hits;
    return result;
}

}  // namespace rtlab::shaders
