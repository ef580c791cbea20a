// buildMaterialShaderTable: records per (geometry slot, ray type) reach the
// right material's shaders through the DXR formula with automatic instance
// contributions.
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <gtest/gtest.h>

using namespace rtlab;
using namespace rtlab::ecs;

TEST(MaterialShaderTable, RayTypeAndMaterialSelectTheRecord) {
    World world;
    Material red, blue;
    red.name = "red";
    blue.name = "blue";
    const MaterialId redId = world.addMaterial(red), blueId = world.addMaterial(blue);
    // Mesh 0: one quad (blue) at z = -2; mesh 1: two geometries, red quad at z = -5 and blue box far away.
    const MeshId near = world.addMesh(load::makeMesh("near", load::makeQuad(1.f, 1.f, blueId)));
    MeshAsset two = load::makeMesh("far", load::makeQuad(1.f, 1.f, redId));
    two.geometries.push_back(load::makeBox(vec3(0.1f), blueId));
    const MeshId far = world.addMesh(std::move(two));
    const Entity a = world.create("a"), b = world.create("b");
    world.emplace(a, LocalTransform{vec3(0.f, 0.f, -2.f)});
    world.emplace(a, MeshInstance{near});
    world.emplace(b, LocalTransform{vec3(3.f, 0.f, -5.f)});
    world.emplace(b, MeshInstance{far});
    const SceneSnapshot snap = makeSnapshot(world, world.update(0.f));
    tracer::AccelManager accel;
    accel.update(snap);

    struct Payload {
        std::string tag;
    };
    using P = tracer::Pipeline<Payload>;
    P::Desc desc;
    desc.rayTypeCount = 2;
    desc.hitGroups = tracer::buildMaterialShaderTable<Payload>(
        accel, snap, 2, [](const Material& m, const Geometry&, std::uint32_t rayType) {
            P::HitGroup g;
            g.closestHit = [tag = m.name + "/" + std::to_string(rayType)](
                               const tracer::HitContext&, Payload& p, const tracer::HitAttributes&) { p.tag = tag; };
            return g;
        });
    desc.missShaders.push_back([](const tracer::MissContext&, Payload& p) { p.tag = "miss"; });
    ASSERT_EQ(desc.hitGroups.size(), 6u);  // 3 geometry slots x 2 ray types
    const P pipeline(accel, std::move(desc));

    auto shoot = [&](const vec3& origin, std::uint32_t rayType) {
        Payload p;
        pipeline.traceRay(tracer::TraceArgs{tracer::RayFlag::None, 0xff, rayType, 2, 0},
                          tracer::RayDesc{origin, 0.f, vec3(0, 0, -1), kInfinity}, p);
        return p.tag;
    };
    EXPECT_EQ(shoot(vec3(0.f), 0), "blue/0");
    EXPECT_EQ(shoot(vec3(0.f), 1), "blue/1");
    EXPECT_EQ(shoot(vec3(3.f, 0.2f, 0.f), 0), "red/0");
    EXPECT_EQ(shoot(vec3(3.f, 0.2f, 0.f), 1), "red/1");
    EXPECT_EQ(shoot(vec3(3.f, 0.f, 0.f), 1), "blue/1");  // the small box (geometry 1) sits in front of the red quad
    EXPECT_EQ(shoot(vec3(9.f, 0.f, 0.f), 0), "miss");
}
