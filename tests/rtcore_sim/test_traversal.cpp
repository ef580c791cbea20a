// The functional traversal: the watertight triangle test, the slab test, and
// closest hits through the two-level BVH against a brute-force reference.
#include "rtcore_test_helpers.hpp"
#include "rtcore_timing_helpers.hpp"

#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>
#include <rtlab/tracer/watertight_triangle.hpp>

#include <gtest/gtest.h>

#include <limits>

using namespace rtlab;
using namespace rtlab::rtcore_sim;
using rtlab::rtcore_sim::test_support::bruteForceClosestHit;
using rtlab::rtcore_sim::test_support::makeSoupMesh;
using rtlab::rtcore_sim::test_support::TestRandom;
using rtlab::tracer::intersectTriangleWatertight;

using rtlab::rtcore_sim::test_support::makeModelRay;
using rtlab::rtcore_sim::test_support::oneTriangleGeometry;

// ---------------------------------------------------------------------------
// Triangle and box tests.

TEST(RtCoreTraversal, LiteralOneTriangleOneRay) {
    // The model tests triangles with the tracer's watertight test (the Embree
    // back end's). Ray straight down the z axis onto the triangle (0,0,0)
    // (1,0,0) (0,1,0): hit at (0.25, 0.25, 0), t = 1, (u, v) = (0.25, 0.25), all exact.
    const auto hit = intersectTriangleWatertight(vec3(0.25f, 0.25f, 1.f), vec3(0.f, 0.f, -1.f), vec3(0.f),
                                                 vec3(1.f, 0.f, 0.f), vec3(0.f, 1.f, 0.f), 0.f, kInfinity);
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->t, 1.f);
    EXPECT_EQ(hit->b1, 0.25f);
    EXPECT_EQ(hit->b2, 0.25f);
}

TEST(RtCoreTraversal, LiteralOneTriangleThroughTheTwoLevelBvh) {
    // The same triangle as a mesh instanced 2 units down z and scaled x2 in x:
    // the ray meets it at world (0.5, 0.25, -2), t = 3, same barycentrics.
    ecs::World world;
    world.addMaterial({});
    const ecs::MeshId mesh = world.addMesh(
        ecs::load::makeMesh("tri", oneTriangleGeometry(vec3(0.f), vec3(1.f, 0.f, 0.f), vec3(0.f, 1.f, 0.f))));
    const ecs::Entity e = world.create("tri");
    world.emplace(e, ecs::LocalTransform{vec3(0.f, 0.f, -2.f), quat(1, 0, 0, 0), vec3(2.f, 1.f, 1.f)});
    world.emplace(e, ecs::MeshInstance{mesh});
    ModelScene model;
    model.update(ecs::makeSnapshot(world, world.update(0.f)));

    TraversalCounters counters;
    const ModelHit hit = traceClosestHit(model, makeModelRay(vec3(0.5f, 0.25f, 1.f), vec3(0.f, 0.f, -1.f)), counters);
    ASSERT_TRUE(hit.hit);
    EXPECT_EQ(hit.t, 3.f);
    EXPECT_EQ(hit.instanceIndex, 0u);
    EXPECT_EQ(hit.geometryIndex, 0u);
    EXPECT_EQ(hit.primitiveIndex, 0u);
    EXPECT_EQ(hit.b0, 0.5f);
    EXPECT_EQ(hit.b1, 0.25f);
    EXPECT_EQ(hit.b2, 0.25f);
    // Both roots are leaves: one TLAS leaf, one instance transition, one BLAS leaf, one triangle.
    EXPECT_EQ(counters.nodeVisits, 0u);
    EXPECT_EQ(counters.boxTests, 0u);
    EXPECT_EQ(counters.leafVisits, 2u);
    EXPECT_EQ(counters.instanceTransitions, 1u);
    EXPECT_EQ(counters.triangleTests, 1u);
    EXPECT_EQ(counters.maxStackDepth, 0u);

    // Missing it beside the triangle still costs the same work.
    TraversalCounters missCounters;
    EXPECT_FALSE(traceClosestHit(model, makeModelRay(vec3(1.5f, 0.75f, 1.f), vec3(0.f, 0.f, -1.f)), missCounters).hit);
    EXPECT_EQ(missCounters.triangleTests, 1u);
}

TEST(RtCoreTraversal, TriangleTestIntervalsFacesAndDegenerates) {
    const vec3 p0(0.f), p1(1.f, 0.f, 0.f), p2(0.f, 1.f, 0.f);
    const vec3 origin(0.25f, 0.25f, 1.f), down(0.f, 0.f, -1.f);
    const auto test = [&](const vec3& o, const vec3& d, float tMin, float tMax, const vec3& q2) {
        return intersectTriangleWatertight(o, d, p0, p1, q2, tMin, tMax).has_value();
    };
    EXPECT_TRUE(test(origin, down, 0.f, 1.001f, p2));
    EXPECT_FALSE(test(origin, down, 0.f, 1.f, p2));                          // t == tMax is outside (tMin, tMax)
    EXPECT_FALSE(test(origin, down, 1.f, kInfinity, p2));                    // t == tMin is outside too
    EXPECT_FALSE(test(origin, -down, 0.f, kInfinity, p2));                   // behind the origin
    EXPECT_TRUE(test(vec3(0.25f, 0.25f, -1.f), -down, 0.f, kInfinity, p2));  // back face: no culling
    EXPECT_FALSE(test(vec3(0.75f, 0.75f, 1.f), down, 0.f, kInfinity, p2));   // outside the hypotenuse
    EXPECT_FALSE(test(vec3(0.25f, 0.25f, 0.f), vec3(1.f, 0.f, 0.f), 0.f, kInfinity, p2));  // in-plane
    EXPECT_FALSE(test(origin, down, 0.f, kInfinity, vec3(2.f, 0.f, 0.f)));                 // degenerate (collinear)
    // Exactly on a vertex and on an edge: hit (edge functions of zero count as inside).
    EXPECT_TRUE(test(vec3(0.f, 0.f, 1.f), down, 0.f, kInfinity, p2));
    EXPECT_TRUE(test(vec3(0.5f, 0.5f, 1.f), down, 0.f, kInfinity, p2));
}

TEST(RtCoreTraversal, TriangleTestIsWatertightOnAClosedMesh) {
    // Rays from points inside a closed icosphere (shared vertices) must leave
    // through some triangle, including rays aimed exactly at vertices.
    const ecs::Geometry sphere = ecs::load::makeIcosphere(1.f, 3, 0);
    TestRandom rng(7);
    std::uint32_t misses = 0, rays = 0;
    for (int i = 0; i < 3000; ++i) {
        const vec3 origin = rng.point(-0.3f, 0.3f);
        vec3 direction = i % 3 == 0 ? sphere.positions[i % sphere.positions.size()] - origin : rng.point(-1.f, 1.f);
        if (glm::dot(direction, direction) == 0.f) continue;
        ++rays;
        bool hit = false;
        for (std::size_t t = 0; t < sphere.triangleCount() && !hit; ++t)
            hit = intersectTriangleWatertight(origin, direction, sphere.positions[sphere.indices[3 * t]],
                                              sphere.positions[sphere.indices[3 * t + 1]],
                                              sphere.positions[sphere.indices[3 * t + 2]], 0.f, kInfinity)
                      .has_value();
        misses += hit ? 0 : 1;
    }
    EXPECT_GT(rays, 2900u);
    EXPECT_EQ(misses, 0u);
}

TEST(RtCoreTraversal, BoxTest) {
    const Aabb box{vec3(-1.f), vec3(1.f)};
    const auto hit = [&](const vec3& o, const vec3& d, float tMin = 0.f, float tMax = kInfinity) {
        return intersectBox(box, o, reciprocalDirection(d), tMin, tMax);
    };
    ASSERT_TRUE(hit(vec3(0.f, 0.f, 5.f), vec3(0.f, 0.f, -1.f)));
    EXPECT_EQ(*hit(vec3(0.f, 0.f, 5.f), vec3(0.f, 0.f, -1.f)), 4.f);          // entry distance
    EXPECT_EQ(*hit(vec3(0.f), vec3(0.f, 0.f, -1.f)), 0.f);                    // inside: tMin
    EXPECT_FALSE(hit(vec3(0.f, 2.f, 5.f), vec3(0.f, 0.f, -1.f)));             // passes above
    EXPECT_FALSE(hit(vec3(0.f, 0.f, 5.f), vec3(0.f, 0.f, 1.f)));              // points away
    EXPECT_FALSE(hit(vec3(0.f, 0.f, 5.f), vec3(0.f, 0.f, -1.f), 0.f, 3.9f));  // ends before the box
    EXPECT_TRUE(hit(vec3(1.f, 0.f, 5.f), vec3(0.f, 0.f, -1.f)));  // along a face (zero direction components)
    EXPECT_TRUE(hit(vec3(1.f, 1.f, 5.f), vec3(0.f, 0.f, -1.f)));  // along an edge
    EXPECT_FALSE(
        intersectBox(Aabb{}, vec3(0.f), reciprocalDirection(vec3(1.f, 1.f, 1.f)), 0.f, kInfinity));  // empty box
    // A flat box (a quad's bounds) is hit by a ray crossing its plane.
    EXPECT_TRUE(intersectBox(Aabb{vec3(-1.f, 0.f, -1.f), vec3(1.f, 0.f, 1.f)}, vec3(0.3f, 2.f, 0.1f),
                             reciprocalDirection(vec3(0.f, -1.f, 0.f)), 0.f, kInfinity));
}

// ---------------------------------------------------------------------------
// Two-level traversal.

TEST(RtCoreTraversal, InstanceMaskSkipsInstances) {
    ecs::World world;
    world.addMaterial({});
    const ecs::MeshId quad = world.addMesh(ecs::load::makeMesh("quad", ecs::load::makeQuad(2.f, 2.f, 0)));
    const ecs::Entity front = world.create("front");
    world.emplace(front, ecs::LocalTransform{vec3(0.f, 0.f, -1.f)});
    world.emplace(front, ecs::MeshInstance{quad, 0x02});
    const ecs::Entity back = world.create("back");
    world.emplace(back, ecs::LocalTransform{vec3(0.f, 0.f, -3.f)});
    world.emplace(back, ecs::MeshInstance{quad, 0x01});
    ModelScene model;
    model.update(ecs::makeSnapshot(world, world.update(0.f)));

    ModelRay ray = makeModelRay(vec3(0.1f, 0.2f, 1.f), vec3(0.f, 0.f, -1.f));
    TraversalCounters counters;
    ModelHit hit = traceClosestHit(model, ray, counters);
    ASSERT_TRUE(hit.hit);
    EXPECT_EQ(hit.instanceIndex, 0u);  // the front quad
    EXPECT_FLOAT_EQ(hit.t, 2.f);
    ray.mask = 0x01;  // only the back quad
    counters = {};
    hit = traceClosestHit(model, ray, counters);
    ASSERT_TRUE(hit.hit);
    EXPECT_EQ(hit.instanceIndex, 1u);
    EXPECT_FLOAT_EQ(hit.t, 4.f);
    EXPECT_EQ(counters.instanceTransitions, 1u);  // the masked instance is never entered
    ray.mask = 0x04;
    EXPECT_FALSE(traceClosestHit(model, ray, counters).hit);
}

// Random soup meshes under random instance transforms and masks, random rays
// with random intervals: the traversal finds exactly the brute-force hit.
TEST(RtCoreTraversal, EqualsBruteForceOnRandomScenes) {
    std::uint64_t rays = 0, hits = 0, exactTies = 0;
    for (std::uint32_t seed = 1; seed <= 4; ++seed) {
        TestRandom rng(seed);
        ecs::World world;
        world.addMaterial({});
        std::vector<ecs::MeshId> meshes;
        for (std::uint32_t m = 0; m < 3; ++m)
            meshes.push_back(world.addMesh(makeSoupMesh(60 + 70 * m, seed * 10 + m, 1.f, 0.25f)));
        for (std::uint32_t i = 0; i < 7; ++i) {
            const ecs::Entity e = world.create("instance");
            const quat rotation =
                glm::angleAxis(rng.range(0.f, 6.f), glm::normalize(rng.point(-1.f, 1.f) + vec3(0.01f)));
            world.emplace(e, ecs::LocalTransform{rng.point(-3.f, 3.f), rotation, vec3(rng.range(0.5f, 2.f))});
            world.emplace(e, ecs::MeshInstance{meshes[i % meshes.size()], static_cast<std::uint8_t>(1u << (i % 3))});
        }
        for (std::uint32_t width : {2u, 4u, 6u, 8u})
            for (BuildQuality quality : {BuildQuality::Medium, BuildQuality::High}) {
                BvhParams params;
                params.width = width;
                params.maxLeafSize = 1 + seed % 4;
                params.tlasMaxLeafSize = 1 + width % 3;
                params.buildQuality = quality;
                ModelScene model(params);
                const ecs::SceneSnapshot snapshot = ecs::makeSnapshot(world, world.update(0.f));
                model.update(snapshot);
                for (int r = 0; r < 300; ++r) {
                    ModelRay ray = makeModelRay(rng.point(-6.f, 6.f), rng.point(-1.f, 1.f));
                    if (r % 2 == 0) ray.direction = rng.point(-2.f, 2.f) - ray.origin;  // aimed into the cluster
                    if (r % 5 == 0) ray.tMin = rng.range(0.f, 2.f);
                    if (r % 7 == 0) ray.tMax = rng.range(2.f, 8.f);
                    ray.mask = r % 11 == 0 ? static_cast<std::uint8_t>(1u << (r % 3)) : 0xff;
                    TraversalCounters counters;
                    const ModelHit got = traceClosestHit(model, ray, counters);
                    const ModelHit want = bruteForceClosestHit(model, *snapshot.meshes, ray);
                    ++rays;
                    ASSERT_EQ(got.hit, want.hit) << "seed " << seed << " width " << width << " ray " << r;
                    // Work is bounded by the structure.
                    EXPECT_LE(counters.instanceTransitions, model.instances().size());
                    EXPECT_GE(counters.boxTests, 2 * counters.nodeVisits);
                    EXPECT_LE(counters.boxTests, width * counters.nodeVisits);
                    if (!got.hit) continue;
                    ++hits;
                    ASSERT_EQ(got.t, want.t) << "seed " << seed << " width " << width << " ray " << r;
                    if (got.instanceIndex != want.instanceIndex || got.geometryIndex != want.geometryIndex ||
                        got.primitiveIndex != want.primitiveIndex) {
                        ++exactTies;  // two triangles at exactly the same t; the traversal's must really be there
                        const ModelInstance& inst = model.instances()[got.instanceIndex];
                        const ecs::Geometry& g = (*snapshot.meshes)[inst.mesh].geometries[got.geometryIndex];
                        const vec3 o = vec3(inst.objectFromWorld * glm::dvec4(glm::dvec3(ray.origin), 1.0));
                        const vec3 d = vec3(glm::dmat3(inst.objectFromWorld) * glm::dvec3(ray.direction));
                        const auto check = intersectTriangleWatertight(
                            o, d, g.positions[g.indices[3 * got.primitiveIndex]],
                            g.positions[g.indices[3 * got.primitiveIndex + 1]],
                            g.positions[g.indices[3 * got.primitiveIndex + 2]], ray.tMin, kInfinity);
                        ASSERT_TRUE(check);
                        EXPECT_EQ(check->t, got.t);
                    } else {
                        EXPECT_EQ(got.b1, want.b1);
                        EXPECT_EQ(got.b2, want.b2);
                    }
                }
            }
    }
    EXPECT_EQ(rays, 4u * 4u * 2u * 300u);
    EXPECT_GT(hits, rays / 8);
    EXPECT_LE(exactTies, rays / 1000);
}

TEST(RtCoreTraversal, CountersAreDeterministicAndOrderingCullsWork) {
    // A row of boxes along -z: the nearest-first order finds the first box and
    // culls the rest, so a ray down the row tests far fewer triangles than there are.
    ecs::World world;
    world.addMaterial({});
    const ecs::MeshId box = world.addMesh(ecs::load::makeMesh("box", ecs::load::makeBox(vec3(1.f), 0)));
    for (int i = 0; i < 32; ++i) {
        const ecs::Entity e = world.create("box");
        world.emplace(e, ecs::LocalTransform{vec3(0.f, 0.f, -3.f * i)});
        world.emplace(e, ecs::MeshInstance{box});
    }
    ModelScene model;
    model.update(ecs::makeSnapshot(world, world.update(0.f)));
    const ModelRay ray = makeModelRay(vec3(0.1f, 0.2f, 5.f), vec3(0.f, 0.f, -1.f));
    TraversalCounters first, second;
    const ModelHit a = traceClosestHit(model, ray, first);
    const ModelHit b = traceClosestHit(model, ray, second);
    ASSERT_TRUE(a.hit);
    EXPECT_FLOAT_EQ(a.t, 4.5f);
    EXPECT_EQ(a.t, b.t);
    EXPECT_EQ(first.nodeVisits, second.nodeVisits);
    EXPECT_EQ(first.boxTests, second.boxTests);
    EXPECT_EQ(first.triangleTests, second.triangleTests);
    EXPECT_EQ(first.instanceTransitions, second.instanceTransitions);
    EXPECT_EQ(first.maxStackDepth, second.maxStackDepth);
    EXPECT_LE(first.instanceTransitions, 2u);
    EXPECT_LT(first.triangleTests, 32u * 12u / 4u);
    EXPECT_GE(first.maxStackDepth, 1u);
}
