// Your own ray-tracing program on rtlab: a payload and the four shader kinds
// (ray generation, closest-hit, any-hit, miss) as C++ callables, traced once
// with Embree and once through the cycle-counted RT-core model, whose cycle
// count is printed. The two images must be bit-identical (exit 1 otherwise).
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <cstdio>
#include <vector>

using namespace rtlab;

namespace {

// What one ray carries through its shaders.
struct Payload {
    vec3 color{0.f};
    float distance = 0.f;
};

// A floor, a sphere and an alpha-masked fence in front of it (the fence's
// any-hit shader cuts slots into it), seen by a camera entity.
void buildScene(ecs::World& world) {
    ecs::Material floor, sphere, fence;
    floor.baseColor = vec4(0.7f, 0.7f, 0.7f, 1.f);
    sphere.baseColor = vec4(0.9f, 0.3f, 0.2f, 1.f);
    fence.baseColor = vec4(0.2f, 0.5f, 0.9f, 1.f);
    fence.alphaMode = ecs::AlphaMode::Mask;  // non-opaque: the any-hit shader runs for it
    const ecs::MaterialId floorMat = world.addMaterial(floor), sphereMat = world.addMaterial(sphere),
                          fenceMat = world.addMaterial(fence);
    auto place = [&](const char* name, ecs::Geometry g, vec3 at) {
        const ecs::Entity e = world.create(name);
        world.emplace(e, ecs::LocalTransform{at, quat(1.f, 0.f, 0.f, 0.f), vec3(1.f)});
        ecs::MeshInstance instance;
        instance.mesh = world.addMesh(ecs::load::makeMesh(name, std::move(g)));
        world.emplace(e, instance);
    };
    place("floor", ecs::load::makeGrid(8.f, 4, floorMat), vec3(0.f));
    place("sphere", ecs::load::makeIcosphere(1.f, 3, sphereMat), vec3(0.f, 1.f, 0.f));
    place("fence", ecs::load::makeQuad(3.f, 1.f, fenceMat), vec3(0.f, 0.8f, 1.6f));
    const ecs::Entity camera = world.create("camera");
    const vec3 eye(0.4f, 2.0f, 6.f);
    world.emplace(camera, ecs::LocalTransform{eye, orientationLookingAlong(vec3(0.f, 0.8f, 0.f) - eye), vec3(1.f)});
    world.emplace(camera, ecs::Camera{});
    world.setActiveCamera(camera);
}

struct Render {
    std::vector<vec3> pixels;
    tracer::TraceCounters counters;
};

// Traces one image through `pipeline`'s shaders (back end = whatever the
// pipeline was built with).
Render render(const tracer::Pipeline<Payload>& pipeline, const ecs::SceneSnapshot& scene, int width, int height) {
    Render out;
    out.pixels.resize(std::size_t(width) * height);
    const shaders::PinholeCamera camera(scene.camera, width, height);
    // Ray generation: one primary ray per pixel centre, each its own TraceRay
    // (on the RT-core model one ray per batch: latency-bound; dispatchCoherent
    // hands the model a 16x16 tile of rays at once).
    out.counters = pipeline.dispatchRays(width, height, [&](int x, int y) {
        const shaders::CameraRay r = camera.ray(float(x) + 0.5f, float(y) + 0.5f);
        Payload payload;
        pipeline.traceRay(tracer::TraceArgs{}, tracer::RayDesc{r.origin, 0.f, r.direction, kInfinity}, payload);
        out.pixels[std::size_t(y) * width + x] = payload.color;
    });
    return out;
}

std::uint64_t fnv1a(const std::vector<vec3>& pixels) {
    std::uint64_t h = 1469598103934665603ull;
    for (const vec3& p : pixels)
        for (int c = 0; c < 3; ++c) {
            std::uint32_t bits;
            std::memcpy(&bits, &p[c], 4);
            for (int b = 0; b < 4; ++b) h = (h ^ ((bits >> (8 * b)) & 0xffu)) * 1099511628211ull;
        }
    return h;
}

}  // namespace

int main() {
    ecs::World world;
    buildScene(world);
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    tracer::AccelManager accel;
    accel.update(scene);

    // The shader table: one hit group per geometry (a single ray type).
    tracer::Pipeline<Payload>::Desc desc;
    desc.hitGroups.resize(accel.geometrySlotCount());
    for (auto& group : desc.hitGroups) {
        group.closestHit = [&](const tracer::HitContext& c, Payload& p, const tracer::HitAttributes& a) {
            const ecs::Geometry& g = (*scene.meshes)[c.instance->mesh].geometries[c.geometryIndex];
            const shaders::SurfacePoint s =
                shaders::surfacePoint(scene, accel.instanceFacts(c.instanceIndex).normalFromObject, c, a);
            const float light =
                0.25f + 0.75f * std::max(0.f, glm::dot(s.shadingNormal, glm::normalize(vec3(-1, 2, 1))));
            p.color = vec3((*scene.materials)[g.material].baseColor) * light;
            p.distance = c.rayTCurrent;
        };
        // Any-hit (non-opaque geometry only): slots in the fence are holes.
        group.anyHit = [](const tracer::HitContext& c, Payload&, const tracer::HitAttributes&) {
            const vec3 p = c.worldHitPosition();
            return std::fmod(p.x + 10.f, 0.5f) < 0.2f ? tracer::AnyHitResult::Ignore : tracer::AnyHitResult::Accept;
        };
    }
    desc.missShaders.push_back([](const tracer::MissContext& c, Payload& p) {
        p.color = glm::mix(vec3(0.9f), vec3(0.4f, 0.6f, 1.f), std::max(0.f, c.worldRayDirection.y));
    });

    const int width = 160, height = 90;
    const tracer::Pipeline<Payload> onEmbree(accel, desc);
    const Render embree = render(onEmbree, scene, width, height);

    // The same shaders through the RT-core model (docs/rtcore-model.md).
    rtcore_sim::RtCoreBackend model(rtcore_sim::RtCoreConfig{});
    model.update(scene);
    model.beginFrame();
    const tracer::Pipeline<Payload> onModel(accel, desc, &model);
    const Render rtcore = render(onModel, scene, width, height);
    const nlohmann::json stats = model.statsJson();

    std::printf("rays: %llu (hits %llu, any-hit calls %llu)\n", (unsigned long long)embree.counters.totalRays(),
                (unsigned long long)embree.counters.hits[0], (unsigned long long)embree.counters.anyHitInvocations);
    std::printf("image hash: embree %016llx, rtcore %016llx\n", (unsigned long long)fnv1a(embree.pixels),
                (unsigned long long)fnv1a(rtcore.pixels));
    std::printf("RT-core model: %llu cycles, %.3f rays/cycle\n",
                (unsigned long long)stats["frame"]["cycles"].get<std::uint64_t>(),
                stats["frame"]["raysPerCycle"].get<double>());
    if (embree.pixels != rtcore.pixels || embree.counters.anyHitInvocations == 0 ||
        stats["frame"]["cycles"].get<std::uint64_t>() == 0) {
        std::fprintf(stderr, "custom_shaders: the back ends disagree or nothing was traced\n");
        return 1;
    }
    return 0;
}
