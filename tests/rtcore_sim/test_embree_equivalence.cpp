// The model's traversal must produce Embree's hits: same instance, geometry,
// primitive and t within 1e-6 relative, for the primary rays of the builtin
// scenes and a real glTF file. Rays that hit exactly where two surfaces meet
// (a shared edge or vertex, or two meshes touching) have two correct
// answers at the same t; they are counted separately as ties, never hidden.
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <gtest/gtest.h>

#include <embree3/rtcore.h>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <string>

using namespace rtlab;
using namespace rtlab::rtcore_sim;

namespace {

constexpr float kRelativeTolerance = 1e-6f;
const char* const kEnginePath = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";

struct Comparison {
    std::uint64_t rays = 0;
    std::uint64_t hits = 0;            // rays both back ends hit
    std::uint64_t matches = 0;         // same hit (or both miss)
    // Ties: different primitive, both at the same t (within tolerance).
    std::uint64_t tiesSharedEdge = 0;    // same geometry, the two triangles share an edge
    std::uint64_t tiesSharedVertex = 0;  // same geometry, they share one vertex
    std::uint64_t tiesTouching = 0;      // other geometry or instance at the same t (touching surfaces)
    // Mismatches.
    std::uint64_t hitVersusMiss = 0;
    std::uint64_t tDiffers = 0;          // same primitive, t beyond tolerance
    std::uint64_t otherPrimitive = 0;    // different primitive at a different t
    std::uint64_t mismatches() const { return hitVersusMiss + tDiffers + otherPrimitive; }
    std::uint64_t ties() const { return tiesSharedEdge + tiesSharedVertex + tiesTouching; }
    void add(const Comparison& o) {
        rays += o.rays; hits += o.hits; matches += o.matches;
        tiesSharedEdge += o.tiesSharedEdge; tiesSharedVertex += o.tiesSharedVertex; tiesTouching += o.tiesTouching;
        hitVersusMiss += o.hitVersusMiss; tDiffers += o.tDiffers; otherPrimitive += o.otherPrimitive;
    }
};

std::ostream& operator<<(std::ostream& out, const Comparison& c) {
    return out << "rays " << c.rays << ", hits " << c.hits << ", matches " << c.matches << ", ties " << c.ties()
               << " (shared edge " << c.tiesSharedEdge << ", shared vertex " << c.tiesSharedVertex << ", touching "
               << c.tiesTouching << "), mismatches " << c.mismatches() << " (hit/miss " << c.hitVersusMiss
               << ", t " << c.tDiffers << ", other primitive " << c.otherPrimitive << ")";
}

struct EmbreeHit {
    bool hit = false;
    float t = 0.f;
    std::uint32_t instance = 0, geometry = 0, primitive = 0;
};

EmbreeHit traceEmbree(const tracer::AccelManager& accel, const vec3& origin, const vec3& direction) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh{};
    rh.ray.org_x = origin.x; rh.ray.org_y = origin.y; rh.ray.org_z = origin.z;
    rh.ray.dir_x = direction.x; rh.ray.dir_y = direction.y; rh.ray.dir_z = direction.z;
    rh.ray.tnear = 0.f;
    rh.ray.tfar = kInfinity;
    rh.ray.mask = 0xff;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(accel.tlas(), &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return {};
    return EmbreeHit{true, rh.ray.tfar, rh.hit.instID[0], rh.hit.geomID, rh.hit.primID};
}

// Primary ray through the centre of pixel (x, y), as the preview shader makes it.
ModelRay primaryRay(const ecs::CameraSnapshot& camera, int width, int height, int x, int y) {
    const float aspect = camera.camera.aspectRatio > 0.f ? camera.camera.aspectRatio : float(width) / float(height);
    const float tanHalf = std::tan(0.5f * camera.camera.yfov);
    const float sx = (2.f * (x + 0.5f) / width - 1.f) * tanHalf * aspect;
    const float sy = (1.f - 2.f * (y + 0.5f) / height) * tanHalf;
    const vec3 dirCamera = glm::normalize(vec3(sx, sy, -1.f));
    ModelRay ray;
    ray.origin = vec3(camera.worldFromCamera[3]);
    ray.direction = glm::normalize(mat3(camera.worldFromCamera) * dirCamera);
    return ray;
}

int sharedVertices(const ecs::Geometry& g, std::uint32_t a, std::uint32_t b) {
    int shared = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (g.positions[g.indices[3 * a + i]] == g.positions[g.indices[3 * b + j]]) {
                ++shared;
                break;
            }
    return shared;
}

Comparison compareFrame(const ecs::SceneSnapshot& snapshot, const tracer::AccelManager& accel, const ModelScene& model,
                        int width, int height, const std::string& label) {
    Comparison c;
    int printed = 0;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const ModelRay ray = primaryRay(snapshot.camera, width, height, x, y);
            TraversalCounters counters;
            const ModelHit m = traceClosestHit(model, ray, counters);
            const EmbreeHit e = traceEmbree(accel, ray.origin, ray.direction);
            ++c.rays;
            if (!m.hit && !e.hit) {
                ++c.matches;
                continue;
            }
            const char* kind = nullptr;
            if (m.hit != e.hit) {
                ++c.hitVersusMiss;
                kind = "hit/miss";
            } else {
                ++c.hits;
                const bool sameT = std::abs(m.t - e.t) <= kRelativeTolerance * e.t;
                const bool samePrimitive =
                    m.instanceIndex == e.instance && m.geometryIndex == e.geometry && m.primitiveIndex == e.primitive;
                if (samePrimitive && sameT) {
                    ++c.matches;
                } else if (samePrimitive) {
                    ++c.tDiffers;
                    kind = "t";
                    const ecs::Geometry& g = (*snapshot.meshes)[snapshot.instances[e.instance].mesh].geometries[e.geometry];
                    const vec3 p0 = g.positions[g.indices[3 * e.primitive]], p1 = g.positions[g.indices[3 * e.primitive + 1]], p2 = g.positions[g.indices[3 * e.primitive + 2]];
                    const vec3 n = glm::normalize(mat3(glm::transpose(glm::inverse(snapshot.instances[e.instance].worldFromObject))) * glm::cross(p1 - p0, p2 - p0));
                    std::cout.precision(9);
                    {
                        const glm::dmat4 inv = glm::inverse(glm::dmat4(snapshot.instances[e.instance].worldFromObject));
                        const glm::dvec3 oo = glm::dvec3(inv * glm::dvec4(glm::dvec3(ray.origin), 1.0));
                        const glm::dvec3 od = glm::dmat3(inv) * glm::dvec3(ray.direction);
                        const glm::dvec3 dn = glm::cross(glm::dvec3(p1) - glm::dvec3(p0), glm::dvec3(p2) - glm::dvec3(p0));
                        const double texact = glm::dot(dn, glm::dvec3(p0) - oo) / glm::dot(dn, od);
                        std::cout << "   exact t " << texact << " model err " << (m.t - texact) / texact << " embree err " << (e.t - texact) / texact << "\n";
                    }
                    std::cout << "   cos " << glm::dot(n, ray.direction) << " rel " << (m.t - e.t) / e.t << " p0 " << p0.x << "," << p0.y << "," << p0.z << "\n";
                } else if (sameT) {
                    if (m.instanceIndex == e.instance && m.geometryIndex == e.geometry) {
                        const ecs::Geometry& g =
                            (*snapshot.meshes)[snapshot.instances[e.instance].mesh].geometries[e.geometry];
                        const int shared = sharedVertices(g, m.primitiveIndex, e.primitive);
                        if (shared >= 2) ++c.tiesSharedEdge;
                        else if (shared == 1) ++c.tiesSharedVertex;
                        else ++c.tiesTouching;
                    } else {
                        ++c.tiesTouching;
                    }
                } else {
                    ++c.otherPrimitive;
                    kind = "other primitive";
                }
            }
            if (kind && printed++ < 8)
                std::cout << "  " << label << " mismatch (" << kind << ") at pixel " << x << "," << y << ": model "
                          << (m.hit ? "" : "miss ") << "inst " << m.instanceIndex << " geom " << m.geometryIndex
                          << " prim " << m.primitiveIndex << " t " << m.t << "; embree " << (e.hit ? "" : "miss ")
                          << "inst " << e.instance << " geom " << e.geometry << " prim " << e.primitive << " t " << e.t
                          << "\n";
        }
    return c;
}

// Loads `source`, runs `frames` updates of `dt` seconds and compares every frame.
Comparison compareScene(const std::string& source, int frames, float dt, int width, int height) {
    ecs::World world;
    ecs::load::loadScene(world, source);
    tracer::AccelManager accel;
    ModelScene model;
    Comparison total;
    for (int f = 0; f < frames; ++f) {
        const ecs::SceneSnapshot snapshot = ecs::makeSnapshot(world, world.update(f == 0 ? 0.f : dt));
        accel.update(snapshot);
        model.update(snapshot);
        const std::string label = std::filesystem::path(source).filename().string() + " frame " + std::to_string(f);
        const Comparison c = compareFrame(snapshot, accel, model, width, height, label);
        std::cout << "[ rtcore   ] " << label << " " << width << "x" << height << ": " << c << "\n";
        total.add(c);
    }
    return total;
}

}  // namespace

TEST(RtCoreEmbreeEquivalence, ShowcasePrimaryRaysThreeFrames) {
    // Frames 1 and 2 move the box (TLAS rebuild) and wave the cloth (BLAS refit).
    const Comparison c = compareScene("builtin:showcase", 3, 0.4f, 320, 240);
    EXPECT_GT(c.hits, c.rays / 2);
    EXPECT_EQ(c.mismatches(), 0u) << c;
}

TEST(RtCoreEmbreeEquivalence, CornellPrimaryRays) {
    const Comparison c = compareScene("builtin:cornell", 1, 0.f, 320, 240);
    EXPECT_GT(c.hits, c.rays / 2);
    EXPECT_EQ(c.mismatches(), 0u) << c;
}

TEST(RtCoreEmbreeEquivalence, TwoCylinderEnginePrimaryRays) {
    if (!std::filesystem::exists(kEnginePath)) GTEST_SKIP() << kEnginePath << " not installed (assimp-testmodels)";
    const Comparison c = compareScene(kEnginePath, 1, 0.f, 320, 240);
    EXPECT_GT(c.hits, c.rays / 4);
    EXPECT_EQ(c.mismatches(), 0u) << c;
}
