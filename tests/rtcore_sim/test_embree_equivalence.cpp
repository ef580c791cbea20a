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

#include <algorithm>
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
    std::uint64_t hits = 0;     // rays both back ends hit
    std::uint64_t matches = 0;  // same instance, geometry, primitive and t (or both miss)
    // Ties: a different primitive at the same t (within tolerance).
    std::uint64_t tiesSharedEdge = 0;    // same geometry, the two triangles share an edge
    std::uint64_t tiesSharedVertex = 0;  // same geometry, they share one vertex
    std::uint64_t tiesTouching = 0;      // another geometry or instance at the same t (surfaces meeting)
    // Within rounding: the disagreement is smaller than float rounding of the
    // instance transform (see RoundingAllowance).
    std::uint64_t boundaryGrazes =
        0;                       // a hit within rounding of its triangle's boundary, the other side did not take it
    std::uint64_t grazingT = 0;  // same primitive, t beyond 1e-6 relative but within rounding at this angle
    // Real mismatches: none of the above.
    std::uint64_t hitVersusMiss = 0;
    std::uint64_t tDiffers = 0;
    std::uint64_t otherPrimitive = 0;

    std::uint64_t ties() const { return tiesSharedEdge + tiesSharedVertex + tiesTouching; }
    std::uint64_t withinRounding() const { return boundaryGrazes + grazingT; }
    std::uint64_t mismatches() const { return hitVersusMiss + tDiffers + otherPrimitive; }
    // Everything that is not a match by the letter of the 1e-6 rule.
    std::uint64_t strictDifferences() const { return ties() + withinRounding() + mismatches(); }
    void add(const Comparison& o) {
        rays += o.rays;
        hits += o.hits;
        matches += o.matches;
        tiesSharedEdge += o.tiesSharedEdge;
        tiesSharedVertex += o.tiesSharedVertex;
        tiesTouching += o.tiesTouching;
        boundaryGrazes += o.boundaryGrazes;
        grazingT += o.grazingT;
        hitVersusMiss += o.hitVersusMiss;
        tDiffers += o.tDiffers;
        otherPrimitive += o.otherPrimitive;
    }
};

std::ostream& operator<<(std::ostream& out, const Comparison& c) {
    return out << "rays " << c.rays << ", both hit " << c.hits << ", matches " << c.matches << "; ties " << c.ties()
               << " (shared edge " << c.tiesSharedEdge << ", shared vertex " << c.tiesSharedVertex << ", touching "
               << c.tiesTouching << "); within rounding " << c.withinRounding() << " (boundary grazes "
               << c.boundaryGrazes << ", grazing t " << c.grazingT << "); mismatches " << c.mismatches()
               << " (hit/miss " << c.hitVersusMiss << ", t " << c.tDiffers << ", other primitive " << c.otherPrimitive
               << ")";
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
    rh.ray.org_x = origin.x;
    rh.ray.org_y = origin.y;
    rh.ray.org_z = origin.z;
    rh.ray.dir_x = direction.x;
    rh.ray.dir_y = direction.y;
    rh.ray.dir_z = direction.z;
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

// The world ray against one triangle in double precision, the instance
// transform inverted in double: the reference both back ends approximate.
struct ExactHit {
    bool valid = false;
    double t = 0.0;
    double boundaryDistance =
        0.0;              // signed object-space distance of the hit point to the triangle's boundary (< 0 outside)
    double cosine = 0.0;  // |cos| of the angle between ray and triangle normal
    double directionLength = 0.0;  // of the object-space direction
    double allowance = 0.0;        // RoundingAllowance: object-space position uncertainty
};

// Float rounding of an instance transform moves the object-space ray by a
// few ulps of the magnitudes involved; 2^-20 (8 ulps) of them is the
// allowance under which two back ends may legitimately disagree.
constexpr double kRoundingAllowance = 1.0 / (1 << 20);

ExactHit exactHit(const ecs::SceneSnapshot& snapshot, const ModelRay& ray, std::uint32_t instance,
                  std::uint32_t geometry, std::uint32_t primitive) {
    const ecs::InstanceSnapshot& inst = snapshot.instances[instance];
    const ecs::Geometry& g = (*snapshot.meshes)[inst.mesh].geometries[geometry];
    const glm::dmat4 objectFromWorld = glm::inverse(glm::dmat4(inst.worldFromObject));
    const glm::dvec3 o = glm::dvec3(objectFromWorld * glm::dvec4(glm::dvec3(ray.origin), 1.0));
    const glm::dvec3 d = glm::dmat3(objectFromWorld) * glm::dvec3(ray.direction);
    const glm::dvec3 p[3] = {glm::dvec3(g.positions[g.indices[3 * primitive]]),
                             glm::dvec3(g.positions[g.indices[3 * primitive + 1]]),
                             glm::dvec3(g.positions[g.indices[3 * primitive + 2]])};
    const glm::dvec3 n = glm::cross(p[1] - p[0], p[2] - p[0]);
    const double denom = glm::dot(n, d);
    ExactHit e;
    if (denom == 0.0 || glm::length(n) == 0.0) return e;
    e.valid = true;
    e.t = glm::dot(n, p[0] - o) / denom;
    e.directionLength = glm::length(d);
    e.cosine = std::abs(denom) / (glm::length(n) * e.directionLength);
    const glm::dvec3 hitPoint = o + e.t * d;
    const glm::dvec3 unitNormal = glm::normalize(n);
    e.boundaryDistance = kInfinity;
    for (int k = 0; k < 3; ++k) {
        const glm::dvec3 a = p[k], b = p[(k + 1) % 3];
        e.boundaryDistance =
            std::min(e.boundaryDistance, glm::dot(glm::cross(b - a, hitPoint - a), unitNormal) / glm::length(b - a));
    }
    // Magnitudes the transform and the hit point computation round.
    const glm::dvec3 worldOrigin(ray.origin);
    const double worldMagnitude = std::max({std::abs(worldOrigin.x), std::abs(worldOrigin.y), std::abs(worldOrigin.z)});
    double linearNorm = 0.0;
    for (int r = 0; r < 3; ++r)
        linearNorm = std::max(linearNorm, std::abs(objectFromWorld[0][r]) + std::abs(objectFromWorld[1][r]) +
                                              std::abs(objectFromWorld[2][r]));
    const glm::dvec3 translation(objectFromWorld[3]);
    const double magnitude = linearNorm * worldMagnitude +
                             std::max({std::abs(translation.x), std::abs(translation.y), std::abs(translation.z)}) +
                             std::abs(e.t) * std::max({std::abs(d.x), std::abs(d.y), std::abs(d.z)});
    e.allowance = kRoundingAllowance * magnitude;
    return e;
}

bool nearBoundary(const ExactHit& e) { return e.valid && std::abs(e.boundaryDistance) <= e.allowance; }

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
                // Step: hit versus miss — fine only when the hit grazes its triangle's boundary.
                const ExactHit x = m.hit ? exactHit(snapshot, ray, m.instanceIndex, m.geometryIndex, m.primitiveIndex)
                                         : exactHit(snapshot, ray, e.instance, e.geometry, e.primitive);
                if (nearBoundary(x)) {
                    ++c.boundaryGrazes;
                } else {
                    ++c.hitVersusMiss;
                    kind = "hit/miss";
                }
            } else {
                ++c.hits;
                const bool sameT = std::abs(m.t - e.t) <= kRelativeTolerance * e.t;
                const bool samePrimitive =
                    m.instanceIndex == e.instance && m.geometryIndex == e.geometry && m.primitiveIndex == e.primitive;
                if (samePrimitive && sameT) {
                    ++c.matches;
                } else if (samePrimitive) {
                    // Step: same primitive, t apart — fine when rounding explains it at this angle.
                    const ExactHit x = exactHit(snapshot, ray, e.instance, e.geometry, e.primitive);
                    const double tAllowance = x.allowance / std::max(x.cosine * x.directionLength, 1e-30);
                    if (x.valid && std::abs(double(m.t) - double(e.t)) <= 2.0 * tAllowance) {
                        ++c.grazingT;
                    } else {
                        ++c.tDiffers;
                        kind = "t";
                    }
                } else if (sameT) {
                    // Step: different primitive at the same t — a tie.
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
                    // Step: different primitives at different t — fine when the nearer one grazes its boundary.
                    const ExactHit x = m.t < e.t
                                           ? exactHit(snapshot, ray, m.instanceIndex, m.geometryIndex, m.primitiveIndex)
                                           : exactHit(snapshot, ray, e.instance, e.geometry, e.primitive);
                    if (nearBoundary(x)) {
                        ++c.boundaryGrazes;
                    } else {
                        ++c.otherPrimitive;
                        kind = "other primitive";
                    }
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

// No real mismatch; ties and rounding-level disagreements stay rare.
void expectEquivalent(const Comparison& c) {
    EXPECT_EQ(c.mismatches(), 0u) << c;
    EXPECT_LE(c.ties() + c.withinRounding(), c.rays / 500) << c;
}

}  // namespace

TEST(RtCoreEmbreeEquivalence, ShowcasePrimaryRaysThreeFrames) {
    // Frames 1 and 2 move the box (TLAS rebuild) and wave the cloth (BLAS refit).
    const Comparison c = compareScene("builtin:showcase", 3, 0.4f, 320, 240);
    EXPECT_GT(c.hits, c.rays / 2);
    expectEquivalent(c);
}

TEST(RtCoreEmbreeEquivalence, CornellPrimaryRays) {
    // The camera sits on the box's symmetry plane, so the ray through every
    // pixel centre on the image diagonals runs exactly along the seams where
    // walls meet: the ties and boundary grazes of this scene.
    const Comparison c = compareScene("builtin:cornell", 1, 0.f, 320, 240);
    EXPECT_GT(c.hits, c.rays / 2);
    expectEquivalent(c);
}

TEST(RtCoreEmbreeEquivalence, TwoCylinderEnginePrimaryRays) {
    if (!std::filesystem::exists(kEnginePath)) GTEST_SKIP() << kEnginePath << " not installed (assimp-testmodels)";
    const Comparison c = compareScene(kEnginePath, 1, 0.f, 320, 240);
    EXPECT_GT(c.hits, c.rays / 4);
    expectEquivalent(c);
}
