// World: entity handles, sparse-set storage, explicit change tracking and the
// FrameUpdate each kind of change lands in.
#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/world.hpp>

#include <gtest/gtest.h>

#include <algorithm>

using namespace rtlab;
using namespace rtlab::ecs;

namespace {

bool contains(const std::vector<Entity>& v, Entity e) { return std::find(v.begin(), v.end(), e) != v.end(); }
bool contains(const std::vector<MeshId>& v, MeshId m) { return std::find(v.begin(), v.end(), m) != v.end(); }

struct ThreeThings {
    World world;
    MeshId rigidMesh{}, morphMesh{}, otherMesh{};
    Entity mover, morpher, bystander;

    ThreeThings() {
        rigidMesh = world.addMesh(load::makeMesh("box", load::makeBox(vec3(1.f), 0)));
        Geometry g = load::makeGrid(1.f, 2, 0);
        g.restPositions = g.positions;
        g.restNormals = g.normals;
        MorphTarget t;
        t.positionDeltas.assign(g.positions.size(), vec3(0.f, 1.f, 0.f));
        g.morphTargets.push_back(t);
        morphMesh = world.addMesh(load::makeMesh("grid", std::move(g)));
        otherMesh = world.addMesh(load::makeMesh("other", load::makeBox(vec3(2.f), 0)));
        mover = world.create("mover");
        world.emplace(mover, LocalTransform{});
        world.emplace(mover, MeshInstance{rigidMesh});
        morpher = world.create("morpher");
        world.emplace(morpher, MeshInstance{morphMesh});
        world.emplace(morpher, MorphWeights{{0.f}});
        bystander = world.create("bystander");
        world.emplace(bystander, LocalTransform{vec3(5.f, 0.f, 0.f)});
        world.emplace(bystander, MeshInstance{otherMesh});
    }
};

}  // namespace

TEST(EntityPool, StaleHandleIsDetectedAfterRecycling) {
    World world;
    const Entity a = world.create("a");
    world.emplace(a, LocalTransform{vec3(1.f)});
    world.destroy(a);
    const Entity b = world.create("b");
    EXPECT_EQ(a.index, b.index);            // index recycled...
    EXPECT_NE(a.generation, b.generation);  // ...with a new generation
    EXPECT_FALSE(world.alive(a));
    EXPECT_TRUE(world.alive(b));
    EXPECT_EQ(world.get<LocalTransform>(a), nullptr);
    EXPECT_EQ(world.get<LocalTransform>(b), nullptr);  // components did not leak to the new entity
    EXPECT_THROW(world.patch<LocalTransform>(a, [](LocalTransform&) {}), std::logic_error);
}

TEST(ComponentStore, RemovalKeepsStoragePacked) {
    ComponentStore<int> s;
    const Entity e0{0, 0}, e1{1, 0}, e2{2, 0};
    s.set(e0, 10);
    s.set(e1, 11);
    s.set(e2, 12);
    EXPECT_TRUE(s.remove(e0));
    ASSERT_EQ(s.size(), 2u);
    EXPECT_EQ(*s.find(e1), 11);
    EXPECT_EQ(*s.find(e2), 12);
    EXPECT_EQ(s.find(e0), nullptr);
    EXPECT_FALSE(s.contains(Entity{1, 7}));  // wrong generation
    int sum = 0;
    for (int v : s.components()) sum += v;
    EXPECT_EQ(sum, 23);
}

TEST(World, EachVisitsOnlyEntitiesWithAllComponents) {
    ThreeThings s;
    int withTransform = 0;
    s.world.each<MeshInstance, LocalTransform>(
        [&](Entity, const MeshInstance&, const LocalTransform&) { ++withTransform; });
    EXPECT_EQ(withTransform, 2);  // morpher has no LocalTransform
    EXPECT_EQ(s.world.count<MeshInstance>(), 3u);
}

TEST(FrameUpdate, FirstUpdateBuildsEverything) {
    ThreeThings s;
    const FrameUpdate u = s.world.update(0.f);
    EXPECT_EQ(u.rebuiltMeshes.size(), 3u);
    EXPECT_TRUE(u.refitMeshes.empty());
    EXPECT_TRUE(u.movedInstances.empty());  // new instances are a TLAS build, not moves
    EXPECT_TRUE(u.instanceSetChanged);
}

TEST(FrameUpdate, NothingChangedMeansNoWork) {
    ThreeThings s;
    s.world.update(0.f);
    const FrameUpdate u = s.world.update(0.1f);
    EXPECT_FALSE(u.geometryChanged());
    EXPECT_TRUE(u.movedInstances.empty());
    EXPECT_TRUE(u.refitMeshes.empty());
    EXPECT_TRUE(u.rebuiltMeshes.empty());
}

TEST(FrameUpdate, MovedInstanceIsTlasOnly) {
    ThreeThings s;
    s.world.update(0.f);
    s.world.patch<LocalTransform>(s.mover, [](LocalTransform& t) { t.translation.x += 1.f; });
    const FrameUpdate u = s.world.update(0.1f);
    ASSERT_EQ(u.movedInstances.size(), 1u);
    EXPECT_EQ(u.movedInstances[0], s.mover);
    EXPECT_TRUE(u.refitMeshes.empty());
    EXPECT_TRUE(u.rebuiltMeshes.empty());
    EXPECT_FALSE(u.instanceSetChanged);
    EXPECT_FALSE(contains(u.movedInstances, s.bystander));
    EXPECT_FLOAT_EQ(s.world.get<WorldTransform>(s.mover)->worldFromObject[3].x, 1.f);
}

TEST(FrameUpdate, PatchWithSameValueStillCountsAsMoveButWorldUnchangedIsNot) {
    // An explicit patch marks dirty; the transform system only reports a move
    // when the world matrix actually changes.
    ThreeThings s;
    s.world.update(0.f);
    s.world.patch<LocalTransform>(s.bystander, [](LocalTransform&) {});
    const FrameUpdate u = s.world.update(0.1f);
    EXPECT_TRUE(u.movedInstances.empty());
}

TEST(FrameUpdate, MorphWeightChangeIsRefit) {
    ThreeThings s;
    s.world.update(0.f);
    s.world.patch<MorphWeights>(s.morpher, [](MorphWeights& w) { w.weights[0] = 0.5f; });
    const FrameUpdate u = s.world.update(0.1f);
    ASSERT_EQ(u.refitMeshes.size(), 1u);
    EXPECT_EQ(u.refitMeshes[0], s.morphMesh);
    EXPECT_TRUE(u.rebuiltMeshes.empty());
    EXPECT_TRUE(u.movedInstances.empty());
    // The deformation system applied the weight to the rest pose.
    const Geometry& g = s.world.mesh(s.morphMesh).geometries[0];
    EXPECT_FLOAT_EQ(g.positions[0].y, g.restPositions[0].y + 0.5f);
}

TEST(FrameUpdate, DeformMeshIsRefitAndTopologyChangeIsRebuild) {
    ThreeThings s;
    s.world.update(0.f);
    s.world.deformMesh(s.rigidMesh, [](MeshAsset& m) { m.geometries[0].positions[0].x += 0.1f; });
    FrameUpdate u = s.world.update(0.1f);
    EXPECT_TRUE(contains(u.refitMeshes, s.rigidMesh));
    EXPECT_TRUE(u.rebuiltMeshes.empty());

    s.world.deformMesh(s.rigidMesh, [](MeshAsset& m) { m.geometries[0].indices.resize(6); });
    u = s.world.update(0.1f);
    EXPECT_TRUE(contains(u.rebuiltMeshes, s.rigidMesh));  // counts changed: promoted to rebuild
    EXPECT_TRUE(u.refitMeshes.empty());

    s.world.replaceMesh(s.otherMesh, load::makeMesh("ico", load::makeIcosphere(1.f, 1, 0)));
    u = s.world.update(0.1f);
    ASSERT_EQ(u.rebuiltMeshes.size(), 1u);
    EXPECT_EQ(u.rebuiltMeshes[0], s.otherMesh);
}

TEST(FrameUpdate, ParentMoveMovesChildInstances) {
    World world;
    const MeshId mesh = world.addMesh(load::makeMesh("box", load::makeBox(vec3(1.f), 0)));
    const Entity root = world.create("root");
    world.emplace(root, LocalTransform{});
    const Entity child = world.create("child");
    world.emplace(child, Parent{root});
    world.emplace(child, LocalTransform{vec3(0.f, 2.f, 0.f)});
    world.emplace(child, MeshInstance{mesh});
    world.update(0.f);
    EXPECT_FLOAT_EQ(world.get<WorldTransform>(child)->worldFromObject[3].y, 2.f);
    world.patch<LocalTransform>(root, [](LocalTransform& t) { t.translation = vec3(1.f, 0.f, 0.f); });
    const FrameUpdate u = world.update(0.1f);
    ASSERT_EQ(u.movedInstances.size(), 1u);
    EXPECT_EQ(u.movedInstances[0], child);
    EXPECT_FLOAT_EQ(world.get<WorldTransform>(child)->worldFromObject[3].x, 1.f);
}

TEST(FrameUpdate, AddingAndRemovingInstancesChangesTheInstanceSet) {
    ThreeThings s;
    s.world.update(0.f);
    s.world.destroy(s.bystander);
    FrameUpdate u = s.world.update(0.1f);
    EXPECT_TRUE(u.instanceSetChanged);
    EXPECT_TRUE(u.rebuiltMeshes.empty());
    const Entity e = s.world.create("new");
    s.world.emplace(e, MeshInstance{s.rigidMesh});
    u = s.world.update(0.1f);
    EXPECT_TRUE(u.instanceSetChanged);
    EXPECT_TRUE(u.movedInstances.empty());
}

TEST(Hierarchy, CycleIsReportedNotLooped) {
    World world;
    const Entity a = world.create("a"), b = world.create("b");
    world.emplace(a, Parent{b});
    world.emplace(b, Parent{a});
    EXPECT_THROW(world.update(0.f), std::logic_error);
}

TEST(Animation, LinearTranslationIsSampledAndLoops) {
    World world;
    const MeshId mesh = world.addMesh(load::makeMesh("box", load::makeBox(vec3(1.f), 0)));
    const Entity e = world.create("animated");
    world.emplace(e, MeshInstance{mesh});
    AnimationClip clip;
    AnimationChannel c;
    c.target = e;
    c.path = AnimationPath::Translation;
    c.times = {0.f, 2.f};
    c.values = {0.f, 0.f, 0.f, 4.f, 0.f, 0.f};
    clip.channels.push_back(c);
    world.addAnimation(clip);
    EXPECT_FLOAT_EQ(world.animationDuration(), 2.f);
    world.update(0.f);
    FrameUpdate u = world.update(0.5f);
    EXPECT_FLOAT_EQ(world.get<LocalTransform>(e)->translation.x, 1.f);
    EXPECT_EQ(u.movedInstances.size(), 1u);
    world.update(2.f);  // t = 2.5 wraps to 0.5
    EXPECT_FLOAT_EQ(world.get<LocalTransform>(e)->translation.x, 1.f);
}

TEST(Animation, StepAndCubicSplineInterpolation) {
    World world;
    const Entity e = world.create("animated");
    AnimationClip clip;
    AnimationChannel step;
    step.target = e;
    step.path = AnimationPath::Scale;
    step.interpolation = Interpolation::Step;
    step.times = {0.f, 1.f, 2.f};
    step.values = {1, 1, 1, 3, 3, 3, 1, 1, 1};
    clip.channels.push_back(step);
    // Cubic spline with zero tangents between 0 and 2: midpoint is exactly 1.
    AnimationChannel cubic;
    cubic.target = e;
    cubic.path = AnimationPath::Translation;
    cubic.interpolation = Interpolation::CubicSpline;
    cubic.times = {0.f, 2.f};
    cubic.values = {0, 0, 0, 0, 0, 0, 0, 0, 0, /*key 1*/ 0, 0, 0, 2, 0, 0, 0, 0, 0};
    clip.channels.push_back(cubic);
    world.addAnimation(clip);
    world.update(0.f);
    world.update(1.0f);
    EXPECT_FLOAT_EQ(world.get<LocalTransform>(e)->scale.x, 3.f);
    EXPECT_NEAR(world.get<LocalTransform>(e)->translation.x, 1.f, 1e-6f);
}

TEST(Skinning, MovingAJointRefitsTheSkinnedMesh) {
    World world;
    Geometry g = load::makeQuad(1.f, 1.f, 0);
    g.restPositions = g.positions;
    g.restNormals = g.normals;
    g.joints.assign(g.positions.size(), glm::uvec4(0, 1, 0, 0));
    g.weights = {vec4(1, 0, 0, 0), vec4(1, 0, 0, 0), vec4(0, 1, 0, 0), vec4(0, 1, 0, 0)};
    const MeshId mesh = world.addMesh(load::makeMesh("skinned quad", std::move(g)));
    const Entity j0 = world.create("joint0"), j1 = world.create("joint1");
    world.emplace(j0, LocalTransform{});
    world.emplace(j1, LocalTransform{});
    const Entity skinned = world.create("skinned");
    world.emplace(skinned, MeshInstance{mesh});
    world.emplace(skinned, Skin{{j0, j1}, {mat4(1.f), mat4(1.f)}});
    world.update(0.f);
    world.patch<LocalTransform>(j1, [](LocalTransform& t) { t.translation.z = 1.f; });
    const FrameUpdate u = world.update(0.1f);
    ASSERT_EQ(u.refitMeshes.size(), 1u);
    EXPECT_EQ(u.refitMeshes[0], mesh);
    EXPECT_TRUE(u.movedInstances.empty());  // skinned instances live in world space
    const Geometry& out = world.mesh(mesh).geometries[0];
    EXPECT_FLOAT_EQ(out.positions[0].z, 0.f);  // bound to joint 0
    EXPECT_FLOAT_EQ(out.positions[2].z, 1.f);  // bound to joint 1
}
