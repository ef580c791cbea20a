// Retained acceleration structures: the FrameUpdate decides the work, and
// the refit-quality policy turns badly degraded refits into rebuilds.
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <gtest/gtest.h>

#include <cmath>

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
    rh.ray.org_x = origin.x;
    rh.ray.org_y = origin.y;
    rh.ray.org_z = origin.z;
    rh.ray.dir_x = dir.x;
    rh.ray.dir_y = dir.y;
    rh.ray.dir_z = dir.z;
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

TEST(AccelManager, InstanceScaledToZeroLeavesTheSnapshotAndComesBack) {
    // A zero scale (glTF hides nodes so) has no inverse: Embree's object-space rays would be invalid.
    Scene s;
    tracer::AccelManager accel;
    s.step(accel, 0.f);
    const vec3 origin(0.f, 0.2f, 5.f), dir(0.f, 0.f, -1.f);
    EXPECT_NEAR(hitDistance(accel, origin, dir), 9.5f, 1e-4f);
    for (const vec3 scale : {vec3(1.f, 0.f, 1.f), vec3(1e-13f), vec3(std::nanf(""))}) {
        s.world.patch<LocalTransform>(s.boxEntity, [&](LocalTransform& t) { t.scale = scale; });
        const SceneSnapshot snapshot = makeSnapshot(s.world, s.world.update(0.1f));
        EXPECT_EQ(snapshot.untraceableInstances, 1u) << scale.x;
        EXPECT_EQ(snapshot.instances.size(), 1u) << scale.x;  // the grid
        // The TLAS is rebuilt when the box leaves it (the first time), not again while it stays out.
        EXPECT_EQ(accel.update(snapshot).tlasBuilds, scale.x == 1.f ? 1u : 0u) << scale.x;
        EXPECT_EQ(hitDistance(accel, origin, dir), -1.f);
    }
    s.world.patch<LocalTransform>(s.boxEntity, [](LocalTransform& t) { t.scale = vec3(1.f); });
    EXPECT_EQ(s.step(accel).tlasBuilds, 1u);
    EXPECT_NEAR(hitDistance(accel, origin, dir), 9.5f, 1e-4f);
}

TEST(AccelManager, DeformedMeshIsRefitAndRaysSeeNewVertices) {
    Scene s;
    tracer::AccelOptions options;
    options.refitQualityCheckInterval = 1;
    tracer::AccelManager accel(options);
    s.step(accel, 0.f);
    // The grid lies in y = 0; lift it by 0.5 through a deformMesh edit.
    EXPECT_NEAR(hitDistance(accel, vec3(0.1f, 5.f, 0.1f), vec3(0.f, -1.f, 0.f)), 5.f, 1e-4f);
    s.world.deformMesh(s.grid, [](MeshAsset& m) {
        for (vec3& p : m.geometries[0].positions) p.y += 0.5f;
    });
    const tracer::AccelUpdateStats st = s.step(accel);
    EXPECT_EQ(st.blasRefit, 1u);
    EXPECT_EQ(st.blasRebuilt, 0u);
    EXPECT_NEAR(st.worstRefitDegradation, 1.f, 1e-6f);  // a pure translation: a rebuild gains nothing
    EXPECT_NEAR(hitDistance(accel, vec3(0.1f, 5.f, 0.1f), vec3(0.f, -1.f, 0.f)), 4.5f, 1e-4f);
}

TEST(AccelManager, RefitThatARebuildCouldImproveBecomesRebuild) {
    // 1024 small disconnected triangles in a row; the deformation moves each
    // one, intact, to a shuffled slot. The build-time groups are now spread
    // across the whole row, while a rebuild would group neighbours again.
    World world;
    world.addMaterial({});
    Geometry g;
    for (std::uint32_t k = 0; k < 1024; ++k) {
        const vec3 base(float(k), 0.f, 0.f);
        for (const vec3& corner : {vec3(0.f), vec3(0.5f, 0.f, 0.f), vec3(0.f, 0.5f, 0.f)}) {
            g.positions.push_back(base + corner);
            g.normals.emplace_back(0.f, 0.f, 1.f);
            g.indices.push_back(static_cast<std::uint32_t>(g.indices.size()));
        }
    }
    g.restPositions = g.positions;
    g.restNormals = g.normals;
    g.morphTargets.push_back(MorphTarget{std::vector<vec3>(g.positions.size(), vec3(0.f)), {}});
    const MeshId mesh = world.addMesh(load::makeMesh("confetti", std::move(g)));
    const Entity e = world.create("confetti");
    world.emplace(e, MeshInstance{mesh});
    tracer::AccelOptions options;
    options.refitQualityCheckInterval = 1;
    tracer::AccelManager accel(options);
    accel.update(makeSnapshot(world, world.update(0.f)));

    world.deformMesh(mesh, [](MeshAsset& m) {
        std::vector<vec3>& p = m.geometries[0].positions;
        for (std::uint32_t k = 0; k < 1024; ++k) {
            const float slot = float((k * 389u) % 1024u);  // a permutation of the slots
            const float dx = slot - float(k);
            for (int v = 0; v < 3; ++v) p[3 * k + v].x += dx;
        }
    });
    const tracer::AccelUpdateStats st = accel.update(makeSnapshot(world, world.update(0.1f)));
    EXPECT_GT(st.worstRefitDegradation, 10.f);
    EXPECT_EQ(st.blasRebuiltForQuality, 1u);
    EXPECT_EQ(st.blasRebuilt, 1u);
    EXPECT_EQ(st.blasRefit, 0u);
    EXPECT_EQ(st.tlasBuilds, 1u);  // the new BLAS object needs new instance pointers

    // After the rebuild the same positions are as good as a rebuild: refits stay refits.
    world.deformMesh(mesh, [](MeshAsset&) {});
    const tracer::AccelUpdateStats again = accel.update(makeSnapshot(world, world.update(0.1f)));
    EXPECT_EQ(again.blasRefit, 1u);
    EXPECT_NEAR(again.worstRefitDegradation, 1.f, 1e-6f);
}

TEST(AccelManager, SmoothDeformationThatARebuildCannotImproveStaysRefit) {
    // A flat grid turning into a wave loosens every group, but a rebuild
    // would group the same neighbours: no rebuild.
    Scene s;
    tracer::AccelOptions options;
    options.refitQualityCheckInterval = 1;
    tracer::AccelManager accel(options);
    s.step(accel, 0.f);
    s.world.deformMesh(s.grid, [](MeshAsset& m) {
        for (vec3& p : m.geometries[0].positions) p.y = 0.3f * std::sin(3.f * p.x + 2.f * p.z);
    });
    const tracer::AccelUpdateStats st = s.step(accel);
    EXPECT_EQ(st.blasRefit, 1u);
    EXPECT_EQ(st.blasRebuiltForQuality, 0u);
    EXPECT_LT(st.worstRefitDegradation, 1.5f);
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

TEST(AccelManager, MixedProceduralAndTriangleGeometriesStayAligned) {
    // Geometry 0 is procedural, geometry 1 a deformable grid: per-geometry
    // side tables (watertight data, refit clusters) must stay index-aligned.
    World world;
    world.addMaterial({});
    MeshAsset mesh;
    Geometry boxes;
    boxes.proceduralBoxes.push_back(Aabb{vec3(5.f), vec3(6.f)});
    mesh.geometries.push_back(std::move(boxes));
    Geometry grid = load::makeGrid(2.f, 8, 0);
    grid.restPositions = grid.positions;
    grid.restNormals = grid.normals;
    grid.morphTargets.push_back(MorphTarget{std::vector<vec3>(grid.positions.size(), vec3(0.f)), {}});
    mesh.geometries.push_back(std::move(grid));
    const MeshId id = world.addMesh(std::move(mesh));
    world.emplace(world.create("mixed"), MeshInstance{id});
    tracer::AccelOptions options;
    options.refitQualityCheckInterval = 1;
    tracer::AccelManager accel(options);
    accel.update(makeSnapshot(world, world.update(0.f)));
    EXPECT_TRUE(accel.anyProcedural());
    world.deformMesh(id, [](MeshAsset& m) {
        for (vec3& p : m.geometries[1].positions) p.y -= 1.f;
    });
    const tracer::AccelUpdateStats st = accel.update(makeSnapshot(world, world.update(0.1f)));
    EXPECT_EQ(st.blasRefit, 1u);
    EXPECT_NEAR(hitDistance(accel, vec3(0.1f, 5.f, 0.1f), vec3(0.f, -1.f, 0.f)), 6.f, 1e-4f);
}
