// G-buffer: primary visibility through 8-wide packets, writing the guides
// every denoiser needs (depth, normals, albedo, roughness, metalness, ids,
// motion vectors, emissive).
#include "../render_context.hpp"
#include "passes.hpp"

#include <rtlab/core/parallel.hpp>
#include <rtlab/tracer/instance_transform.hpp>

#include <optional>

namespace rtlab::shaders::detail {
namespace {

// The hit's object-space point on its triangle as the vertices were in the
// previous frame, for meshes whose vertices deform (morph targets,
// skinning); nullopt for rigid or procedural geometry, or when the topology
// changed since (vertex count differs).
std::optional<vec3> previousDeformedPoint(const RenderContext& ctx, const FrameHistory& previous, const HitPayload& p) {
    if (p.mesh >= previous.deformedPositions.size()) return std::nullopt;
    const auto& geometries = previous.deformedPositions[p.mesh];
    if (p.geometry >= geometries.size()) return std::nullopt;
    const std::vector<vec3>& before = geometries[p.geometry];
    const ecs::Geometry& g = (*ctx.scene.meshes)[p.mesh].geometries[p.geometry];
    if (g.procedural() || before.size() != g.positions.size() || 3 * std::size_t(p.primitive) + 2 >= g.indices.size())
        return std::nullopt;
    const std::uint32_t i0 = g.indices[3 * p.primitive], i1 = g.indices[3 * p.primitive + 1],
                        i2 = g.indices[3 * p.primitive + 2];
    if (i0 >= before.size() || i1 >= before.size() || i2 >= before.size()) return std::nullopt;
    const vec2 b = p.barycentrics;
    const vec3 point = (1.f - b.x - b.y) * before[i0] + b.x * before[i1] + b.y * before[i2];
    return isFinite(point) ? std::optional<vec3>(point) : std::nullopt;
}

}  // namespace

std::uint64_t runGBufferPass(PassFrame& passFrame, tracer::TraceCounters& counters) {
    RenderContext& ctx = passFrame.ctx;
    const FrameHistory& previous = passFrame.history;
    Image& out = passFrame.out.image;
    const int w = ctx.width, h = ctx.height;
    const vec3 forward = -glm::normalize(vec3(ctx.scene.camera.worldFromCamera[2]));
    const PinholeCamera camera(ctx.scene.camera, w, h);
    const std::optional<PinholeCamera> previousCamera =
        previous.valid ? std::optional<PinholeCamera>(PinholeCamera(previous.camera, w, h)) : std::nullopt;
    // Step: the camera rays through the pixel centres, once each (and one
    // column more: a pixel's footprint needs its right neighbour's ray).
    const std::size_t columns = static_cast<std::size_t>(w) + 1;
    std::vector<vec3> directions(columns * static_cast<std::size_t>(h));
    parallelForEach(static_cast<std::size_t>(h), [&](std::size_t y) {
        for (std::size_t x = 0; x < columns; ++x)
            directions[y * columns + x] =
                camera.ray(static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f).direction;
    });
    const vec3 origin = camera.ray(0.5f, 0.5f).origin;
    const auto direction = [&](int x, int y) {
        return directions[static_cast<std::size_t>(y) * columns + static_cast<std::size_t>(x)];
    };
    // Step: primary rays through pixel centres; with recordRayOrder, the
    // pixel of each of the dispatch's threads (the back end's record order).
    if (ctx.settings.recordRayOrder) passFrame.out.primaryRayPixels = tilePixelOrder(w, h);
    counters.add(ctx.pipeline().dispatchCoherent(
        w, h, ctx.args(kRayPrimary),
        [&](int x, int y, HitPayload&) {
            return tracer::RayDesc{origin, 0.f, direction(x, y), kInfinity};
        },
        [&](int x, int y, const HitPayload& p) {
            GPixel& g = ctx.gbuffer[ctx.pixelIndex(x, y)];
            if (!p.hit) return;
            const ecs::Material& m = ctx.material(p.material);
            const CameraRay r{origin, direction(x, y)};
            g.hit = true;
            g.t = p.t;
            g.depth = p.t * glm::dot(r.direction, forward);
            // The pixel's footprint: the primary ray's distance x the angle to the next pixel's ray.
            g.pixelWorld = p.t * glm::length(direction(x + 1, y) - r.direction);
            g.position = p.position;
            g.viewDir = -r.direction;
            g.normal = p.shadingNormal;
            g.geometricNormal = p.geometricNormal;
            g.albedo = p.albedo;
            g.emissive = m.emissive;
            g.roughness = glm::clamp(m.roughness, 0.f, 1.f);
            g.metalness = glm::clamp(m.metallic, 0.f, 1.f);
            g.transmission = glm::clamp(m.transmission, 0.f, 1.f);
            g.frontFace = p.frontFace;
            g.errorScale = p.errorScale;
            g.material = p.material;
            g.mesh = p.mesh;
            g.instance = p.instance;
            // Step: motion — where this surface point was in the previous frame.
            if (previousCamera) {
                vec3 prevWorld = p.position;
                if (p.entity < previous.present.size() && previous.present[p.entity]) {
                    // The instance transform the tracer caches (instance_transform.hpp).
                    vec3 object =
                        tracer::objectSpacePoint(ctx.accel.instanceFacts(p.instance).objectFromWorld, p.position);
                    // A deforming mesh: the same barycentric point of the
                    // triangle's previous (deformed) vertices.
                    if (const auto prevObject = previousDeformedPoint(ctx, previous, p)) object = *prevObject;
                    prevWorld = vec3(previous.worldFromObject[p.entity] * vec4(object, 1.f));
                }
                const std::optional<vec2> prev = previousCamera->project(prevWorld);
                if (prev && std::isfinite(prev->x) && std::isfinite(prev->y))
                    g.motion = *prev - vec2(x + 0.5f, y + 0.5f);
            }
        }));

    // Step: the guide layers, written straight into the image's planes.
    const std::size_t n = ctx.gbuffer.size();
    float* depth = out.addChannel("depth.Z");
    float* roughness = out.addChannel("roughness.Y");
    float* metalness = out.addChannel("metalness.Y");
    float* transmission = out.addChannel("transmission.Y");
    float* meshId = out.addChannel("id.mesh");
    float* instanceId = out.addChannel("id.instance");
    float* motionX = out.addChannel("motion.X");
    float* motionY = out.addChannel("motion.Y");
    float* pixelWorld = out.addChannel("footprint.pixelWorld");
    const std::array<float*, 3> albedo = out.addRgbPlanes("albedo"), normal = out.addRgbPlanes("normal"),
                                geoNormal = out.addRgbPlanes("geonormal"), emissive = out.addRgbPlanes("emissive");
    const auto store = [](const std::array<float*, 3>& planes, std::size_t i, const vec3& v) {
        planes[0][i] = v.x;
        planes[1][i] = v.y;
        planes[2][i] = v.z;
    };
    parallelForChunks(n, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            const GPixel& g = ctx.gbuffer[i];
            store(albedo, i, g.albedo);
            store(normal, i, g.normal);
            store(geoNormal, i, g.geometricNormal);
            store(emissive, i, g.emissive);
            depth[i] = g.depth;
            roughness[i] = g.roughness;
            metalness[i] = g.metalness;
            transmission[i] = g.transmission;
            meshId[i] = g.hit ? float(g.mesh) : -1.f;
            instanceId[i] = g.hit ? float(g.instance) : -1.f;
            motionX[i] = g.motion.x;
            motionY[i] = g.motion.y;
            pixelWorld[i] = g.pixelWorld;
        }
    });
    // G-buffer in memory + its 19 output floats per pixel + the camera rays.
    return n * (sizeof(GPixel) + 19 * sizeof(float)) + directions.size() * sizeof(vec3);
}

}  // namespace rtlab::shaders::detail
