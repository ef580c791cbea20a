// Ray queries without shaders (ray_query.hpp) against the pipeline: the
// same hits bit for bit, coherent or incoherent, in packets or one ray at a
// time; invalid rays miss; DXR's open interval; inactive lanes untouched.
// Plus the SIMD instance transform against the scalar one.
#include <rtlab/core/rng.hpp>
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/instance_transform.hpp>
#include <rtlab/tracer/pipeline.hpp>
#include <rtlab/tracer/ray_query.hpp>

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>

using namespace rtlab;
using namespace rtlab::ecs;

namespace {

struct Payload {
    tracer::CommittedHit hit;
};

// Three instances of a closed icosphere and a cube: rotated, scaled, one far
// from the origin, one sharing the icosphere mesh.
struct QueryScene {
    World world;
    SceneSnapshot snapshot;
    tracer::AccelManager accel;

    explicit QueryScene(bool watertight)
        : accel([&] {
              tracer::AccelOptions o;
              o.watertight = watertight;
              return o;
          }()) {
        world.addMaterial({});
        const MeshId sphere = world.addMesh(load::makeMesh("sphere", load::makeIcosphere(1.f, 3, 0)));
        const MeshId cube = world.addMesh(load::makeMesh("cube", load::makeBox(vec3(0.8f), 0)));
        auto add = [&](MeshId mesh, const vec3& at, const quat& rotation, float scale) {
            const Entity e = world.create("shape");
            world.emplace(e, LocalTransform{at, rotation, vec3(scale)});
            world.emplace(e, MeshInstance{mesh});
        };
        add(sphere, vec3(0.f), quat(1, 0, 0, 0), 1.f);
        add(cube, vec3(2.5f, 0.3f, -0.5f), glm::angleAxis(0.7f, glm::normalize(vec3(1, 2, 3))), 1.3f);
        add(sphere, vec3(-2.f, 1.f, 1.f), glm::angleAxis(-1.1f, vec3(0, 1, 0)), 0.6f);
        snapshot = makeSnapshot(world, world.update(0.f));
        accel.update(snapshot);
    }
};

// Rays from the camera side and from inside the shapes, in all directions,
// from a stateless hash.
std::vector<tracer::RayDesc> testRays(std::size_t count) {
    std::vector<tracer::RayDesc> rays(count);
    for (std::size_t i = 0; i < count; ++i) {
        auto u = [&](std::uint32_t d) {
            return sampleUniform(SampleKey{static_cast<std::uint32_t>(i), 0, 0, 0, 7}, d);
        };
        const bool inside = i % 3 == 0;
        const vec3 origin =
            inside ? vec3(u(0) - 0.5f, u(1) - 0.5f, u(2) - 0.5f) : vec3(8.f * u(0) - 4.f, 6.f * u(1) - 3.f, 6.f + u(2));
        const vec3 target(7.f * u(3) - 3.5f, 4.f * u(4) - 2.f, 3.f * u(5) - 1.5f);
        rays[i] = tracer::RayDesc{origin, 0.f, glm::normalize(target - origin), kInfinity};
    }
    return rays;
}

void expectSameHit(const tracer::QueryHit& q, const tracer::CommittedHit& p, std::size_t ray) {
    ASSERT_EQ(q.hit, p.hit) << "ray " << ray;
    if (!p.hit) return;
    EXPECT_EQ(std::bit_cast<std::uint32_t>(q.t), std::bit_cast<std::uint32_t>(p.t)) << "ray " << ray;
    EXPECT_EQ(std::bit_cast<std::uint32_t>(q.u), std::bit_cast<std::uint32_t>(p.attributes.values[0])) << "ray " << ray;
    EXPECT_EQ(std::bit_cast<std::uint32_t>(q.v), std::bit_cast<std::uint32_t>(p.attributes.values[1])) << "ray " << ray;
    EXPECT_EQ(q.instance, p.instanceIndex) << "ray " << ray;
    EXPECT_EQ(q.geometry, p.geometryIndex) << "ray " << ray;
    EXPECT_EQ(q.primitive, p.primitiveIndex) << "ray " << ray;
}

std::vector<tracer::CommittedHit> pipelineHits(const tracer::AccelManager& accel,
                                               const std::vector<tracer::RayDesc>& rays) {
    tracer::Pipeline<Payload>::Desc desc;
    desc.hitGroups.resize(accel.geometrySlotCount());
    for (auto& g : desc.hitGroups)
        g.closestHit = [](const tracer::HitContext& c, Payload& p, const tracer::HitAttributes& a) {
            p.hit.hit = true;
            p.hit.t = c.rayTCurrent;
            p.hit.instanceIndex = c.instanceIndex;
            p.hit.geometryIndex = c.geometryIndex;
            p.hit.primitiveIndex = c.primitiveIndex;
            p.hit.attributes = a;
        };
    desc.missShaders.push_back([](const tracer::MissContext&, Payload& p) { p.hit = tracer::CommittedHit{}; });
    const tracer::Pipeline<Payload> pipeline(accel, std::move(desc));
    std::vector<tracer::CommittedHit> hits(rays.size());
    for (std::size_t i = 0; i < rays.size(); ++i) {
        Payload p;
        pipeline.traceRay(tracer::TraceArgs{}, rays[i], p);
        hits[i] = p.hit;
    }
    return hits;
}

TEST(RayQuery, ClosestHitsAreThePipelinesBitForBit) {
    for (const bool watertight : {true, false}) {
        SCOPED_TRACE(watertight ? "watertight" : "native triangles");
        const QueryScene scene(watertight);
        const std::vector<tracer::RayDesc> rays = testRays(2048);
        const std::vector<tracer::CommittedHit> expected = pipelineHits(scene.accel, rays);
        std::size_t hits = 0;
        for (std::size_t first = 0; first < rays.size(); first += 8) {
            for (const auto coherence : {tracer::RayCoherence::Coherent, tracer::RayCoherence::Incoherent}) {
                bool active[8];
                for (int i = 0; i < 8; ++i) active[i] = (first / 8 + i) % 5 != 0;  // some lanes off
                tracer::QueryHit out[8];
                bool occluded[8];
                tracer::queryClosest8(scene.accel, &rays[first], active, out, coherence);
                tracer::queryAny8(scene.accel, &rays[first], active, occluded, coherence);
                for (int i = 0; i < 8; ++i) {
                    if (!active[i]) continue;
                    expectSameHit(out[i], expected[first + i], first + i);
                    EXPECT_EQ(occluded[i], expected[first + i].hit) << "ray " << first + i;
                }
            }
            for (std::size_t i = first; i < first + 8; ++i) {
                expectSameHit(tracer::queryClosest(scene.accel, rays[i]), expected[i], i);
                EXPECT_EQ(tracer::queryAny(scene.accel, rays[i]), expected[i].hit);
                hits += expected[i].hit;
            }
        }
        // The ray set hits and misses (the comparison has power both ways).
        EXPECT_GT(hits, rays.size() / 4);
        EXPECT_LT(hits, rays.size());
    }
}

TEST(RayQuery, InvalidRaysMissAndInactiveLanesAreLeftAlone) {
    const QueryScene scene(true);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const vec3 o(0.f, 0.f, 6.f), d(0.f, 0.f, -1.f);  // a valid ray hits the sphere
    tracer::RayDesc rays[8] = {
        {o, 0.f, d, kInfinity},                           // valid: hits
        {vec3(nan, 0.f, 6.f), 0.f, d, kInfinity},         // NaN origin
        {o, 0.f, vec3(0.f, kInfinity, -1.f), kInfinity},  // infinite direction
        {o, -1.f, d, kInfinity},                          // negative TMin
        {o, 3.f, d, 2.f},                                 // TMax < TMin
        {o, 0.f, d, nan},                                 // NaN TMax
        {o, 0.f, vec3(0.f), kInfinity},                   // zero direction
        {o, 0.f, d, kInfinity},                           // inactive
    };
    bool active[8] = {true, true, true, true, true, true, true, false};
    tracer::QueryHit out[8];
    out[7].t = 42.f;  // sentinel
    for (const auto coherence : {tracer::RayCoherence::Coherent, tracer::RayCoherence::Incoherent}) {
        tracer::queryClosest8(scene.accel, rays, active, out, coherence);
        EXPECT_TRUE(out[0].hit);
        EXPECT_NEAR(out[0].t, 5.f, 0.05f);
        for (int i = 1; i < 7; ++i) EXPECT_FALSE(out[i].hit) << "lane " << i;
        EXPECT_EQ(out[7].t, 42.f);
        for (int i = 1; i < 7; ++i) EXPECT_FALSE(tracer::queryClosest(scene.accel, rays[i]).hit) << "ray " << i;
    }
}

TEST(RayQuery, TheIntervalIsOpenAtBothEnds) {
    const QueryScene scene(true);
    const tracer::RayDesc ray{vec3(0.f, 0.f, 6.f), 0.f, vec3(0.f, 0.f, -1.f), kInfinity};
    const tracer::QueryHit first = tracer::queryClosest(scene.accel, ray);
    ASSERT_TRUE(first.hit);
    const float t = first.t;
    auto with = [&](float tMin, float tMax) {
        tracer::RayDesc r = ray;
        r.tMin = tMin;
        r.tMax = tMax;
        return r;
    };
    // TMax at the hit: outside (the far side of the sphere is beyond it).
    EXPECT_FALSE(tracer::queryClosest(scene.accel, with(0.f, t)).hit);
    EXPECT_EQ(tracer::queryClosest(scene.accel, with(0.f, std::nextafter(t, kInfinity))).t, t);
    // TMin at the hit: the next hit is the sphere's far side.
    const tracer::QueryHit beyond = tracer::queryClosest(scene.accel, with(t, kInfinity));
    ASSERT_TRUE(beyond.hit);
    EXPECT_GT(beyond.t, t + 1.f);
    EXPECT_EQ(tracer::queryClosest(scene.accel, with(std::nextafter(t, 0.f), kInfinity)).t, t);
}

// objectSpaceRays8 gives objectSpacePoint/objectSpaceVector's bits lane by
// lane: seeded random transforms (rotation, scales 1e-3..1e4, translations to
// 1e6) and rays (origins to 1e6, signed zeros, tiny and huge directions).
TEST(InstanceTransform, EightLanesGiveTheScalarBits) {
    for (std::uint32_t trial = 0; trial < 200; ++trial) {
        auto u = [&](std::uint32_t d) { return sampleUniform(SampleKey{trial, 0, 0, 0, 11}, d); };
        const float scale = std::pow(10.f, 7.f * u(0) - 3.f);
        const vec3 translation = (vec3(u(1), u(2), u(3)) - 0.5f) * std::pow(10.f, 6.f * u(4));
        const quat rotation = glm::angleAxis(6.3f * u(5), glm::normalize(vec3(u(6), u(7), u(8)) + 0.01f));
        const mat4 worldFromObject = glm::translate(mat4(1.f), translation) * glm::mat4_cast(rotation) *
                                     glm::scale(mat4(1.f), vec3(scale, scale * (0.5f + u(9)), scale));
        const glm::dmat4 m = tracer::objectFromWorldOf(worldFromObject);
        alignas(32) float wo[3][8], wd[3][8], oo[3][8], od[3][8];
        for (int lane = 0; lane < 8; ++lane)
            for (int k = 0; k < 3; ++k) {
                const float a = u(20 + 6 * lane + k) - 0.5f, b = u(23 + 6 * lane + k) - 0.5f;
                wo[k][lane] = lane == 0 ? -0.f : a * std::pow(10.f, 6.f * u(70 + lane));
                wd[k][lane] = lane == 1 ? (k == 0 ? 1.f : -0.f) : b * std::pow(10.f, 4.f * u(80 + lane) - 2.f);
            }
        tracer::objectSpaceRays8(m, wo, wd, oo, od);
        for (int lane = 0; lane < 8; ++lane) {
            const vec3 o = tracer::objectSpacePoint(m, vec3(wo[0][lane], wo[1][lane], wo[2][lane]));
            const vec3 d = tracer::objectSpaceVector(m, vec3(wd[0][lane], wd[1][lane], wd[2][lane]));
            for (int k = 0; k < 3; ++k) {
                ASSERT_EQ(std::bit_cast<std::uint32_t>(oo[k][lane]), std::bit_cast<std::uint32_t>(o[k]))
                    << "trial " << trial << " lane " << lane << " axis " << k;
                ASSERT_EQ(std::bit_cast<std::uint32_t>(od[k][lane]), std::bit_cast<std::uint32_t>(d[k]))
                    << "trial " << trial << " lane " << lane << " axis " << k;
            }
        }
    }
}

}  // namespace
