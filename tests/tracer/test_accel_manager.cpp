// Retained acceleration structures: the FrameUpdate decides the work, and
// the refit-quality policy turns badly degraded refits into rebuilds.
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <gtest/gtest.h>

#include <embree3/rtcore.h>

using namespace rtlab;
using namespace rtlab::ecs;

namespace {

// A deformable grid (one morph target, unused) plus a rigid box.
struct Scene {
    World world;
    MeshId grid{}, box{};
    Entity gridEntity, boxEntity;
    Scene() {
        world.addMaterial({});
        Geometry g = load::makeGrid(2.f, 16, 0);
        g.restPositions = g.positions;
        g.restNormals = g.normals;
        g.morphTargets.push_back(MorphTarget{std::vector<vec3>(g.positions.size(), vec3(0.f)), {}});
        grid = world.addMesh(load::makeMesh("grid", std::move(g)));
        box = world.addMesh(load::makeMesh("box", load::makeBox(vec3(1.f), 0)));
        gridEntity = world.create("grid");
        world.emplace(gridEntity, MeshInstance{grid});
        boxEntity = world.create("box");
        world.emplace(boxEntity, LocalTransform{vec3(0.f, 0.f, -5.f)});
        world.emplace(boxEntity, MeshInstance{box});
    }
    tracer::AccelUpdateStats step(tracer::AccelManager& accel, float dt = 0.1f) {
        return accel.update(makeSnapshot(world, world.update(dt)));
    }
};

float hitDistance(const tracer::AccelManager& accel, const vec3& origin, const vec3& dir) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh{};
    rh.ray.org_x = origin.x; rh.ray.org_y = origin.y; rh.ray.org_z = origin.z;
    rh.ray.dir_x = dir.x; rh.ray.dir_y = dir.y; rh.ray.dir_z = dir.z;
    rh.ray.tfar = kInfinity;
    rh.ray.mask = 0xff;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(accel.tlas(), &ctx, &rh);
    return rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? -1.f : rh.ray.tfar;
}

}  // namespace

TEST(AccelManager, FirstFrameBuildsEverythingThenIdleFramesDoNothing) {
    Scene s;
    tracer::AccelManager accel;
    tracer::AccelUpdateStats st = s.step(accel, 0.f);
    EXPECT_EQ(st.blasRebuilt, 2u);
    EXPECT_EQ(st.tlasBuilds, 1u);
    st = s.step(accel);
    EXPECT_EQ(st.blasRebuilt, 0u);
    EXPECT_EQ(st.blasRefit, 0u);
    EXPECT_EQ(st.blasReused, 2u);
    EXPECT_EQ(st.tlasBuilds, 0u);
    EXPECT_EQ(st.tlasUpdates, 0u);
}

TEST(AccelManager, MovedInstanceUpdatesTlasOnlyAndRaysSeeTheMove) {
    Scene s;
    tracer::AccelManager accel;
    s.step(accel, 0.f);
    // The box's front face is at z = -4.5.
    EXPECT_NEAR(hitDistance(accel, vec3(0.f, 0.2f, 5.f), vec3(0.f, 0.f, -1.f)), 9.5f, 1e-4f);
    s.world.patch<LocalTransform>(s.boxEntity, [](LocalTransform& t) { t.translation = vec3(0.f, 3.f, -5.f); });
    const tracer::AccelUpdateStats st = s.step(accel);
    EXPECT_EQ(st.instancesMoved, 1u);
    EXPECT_EQ(st.tlasUpdates, 1u);
    EXPECT_EQ(st.tlasBuilds, 0u);
    EXPECT_EQ(st.blasRebuilt + st.blasRefit, 0u);
    EXPECT_NEAR(hitDistance(accel, vec3(0.f, 3.2f, 5.f), vec3(0.f, 0.f, -1.f)), 9.5f, 1e-4f);
    EXPECT_EQ(hitDistance(accel, vec3(0.f, 0.2f, 5.f), vec3(0.f, 0.f, -1.f)), -1.f);  // the old place is empty
}

TEST(AccelManager, DeformedMeshIsRefitAndRaysSeeNewVertices) {
    Scene s;
    tracer::AccelManager accel;
    s.step(accel, 0.f);
    // The grid lies in y = 0; lift it by 0.5 through a deformMesh edit.
    EXPECT_NEAR(hitDistance(accel, vec3(0.1f, 5.f, 0.1f), vec3(0.f, -1.f, 0.f)), 5.f, 1e-4f);
    s.world.deformMesh(s.grid, [](MeshAsset& m) {
        for (vec3& p : m.geometries[0].positions) p.y += 0.5f;
    });
    const tracer::AccelUpdateStats st = s.step(accel);
    EXPECT_EQ(st.blasRefit, 1u);
    EXPECT_EQ(st.blasRebuilt, 0u);
    EXPECT_FLOAT_EQ(st.worstRefitDegradation, 1.f);  // a pure translation does not loosen the hierarchy
    EXPECT_NEAR(hitDistance(accel, vec3(0.1f, 5.f, 0.1f), vec3(0.f, -1.f, 0.f)), 4.5f, 1e-4f);
}

TEST(AccelManager, BadlyDegradedRefitBecomesRebuild) {
    Scene s;
    tracer::AccelManager accel;  // default threshold 2.0
    s.step(accel, 0.f);
    // Scatter every vertex pseudo-randomly over the grid's area: build-time
    // neighbourhoods fall apart, which a refit cannot repair.
    s.world.deformMesh(s.grid, [](MeshAsset& m) {
        std::uint32_t h = 12345u;
        for (vec3& p : m.geometries[0].positions) {
            h = h * 1664525u + 1013904223u;
            p.x = ((h >> 8) & 0xffff) / 65535.f * 2.f - 1.f;
            h = h * 1664525u + 1013904223u;
            p.z = ((h >> 8) & 0xffff) / 65535.f * 2.f - 1.f;
        }
    });
    const tracer::AccelUpdateStats st = s.step(accel);
    EXPECT_GT(st.worstRefitDegradation, 2.f);
    EXPECT_EQ(st.blasRebuiltForQuality, 1u);
    EXPECT_EQ(st.blasRebuilt, 1u);
    EXPECT_EQ(st.blasRefit, 0u);
    EXPECT_EQ(st.tlasBuilds, 1u);  // the new BLAS object needs new instance pointers
}

TEST(AccelManager, PolicyCanBeDisabled) {
    Scene s;
    tracer::AccelOptions options;
    options.refitRebuildThreshold = 0.f;
    tracer::AccelManager accel(options);
    s.step(accel, 0.f);
    s.world.deformMesh(s.grid, [](MeshAsset& m) {
        for (std::size_t i = 0; i < m.geometries[0].positions.size(); ++i)
            m.geometries[0].positions[i].x = (i % 7) * 0.3f - 1.f;
    });
    const tracer::AccelUpdateStats st = s.step(accel);
    EXPECT_EQ(st.blasRefit, 1u);
    EXPECT_EQ(st.blasRebuiltForQuality, 0u);
}

TEST(AccelManager, InstanceFactsTrackOpacity) {
    World world;
    Material masked;
    masked.alphaMode = AlphaMode::Mask;
    world.addMaterial({});
    const MaterialId maskedId = world.addMaterial(masked);
    const MeshId opaqueMesh = world.addMesh(load::makeMesh("o", load::makeBox(vec3(1.f), 0)));
    const MeshId maskedMesh = world.addMesh(load::makeMesh("m", load::makeQuad(1.f, 1.f, maskedId)));
    const Entity a = world.create("a");
    world.emplace(a, MeshInstance{opaqueMesh});
    tracer::AccelManager accel;
    accel.update(makeSnapshot(world, world.update(0.f)));
    EXPECT_TRUE(accel.allOpaque());
    const Entity b = world.create("b");
    world.emplace(b, MeshInstance{maskedMesh});
    accel.update(makeSnapshot(world, world.update(0.1f)));
    EXPECT_FALSE(accel.allOpaque());
    world.patch<MeshInstance>(b, [](MeshInstance& m) { m.flags = 0x4; });  // InstanceFlag::ForceOpaque
    accel.update(makeSnapshot(world, world.update(0.1f)));
    EXPECT_TRUE(accel.allOpaque());
}
