// Built-in scenes: contents, and the update categories across frames.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>

#include <gtest/gtest.h>

using namespace rtlab;
using namespace rtlab::ecs;

TEST(BuiltinScenes, ShowcaseHasEveryIngredient) {
    World world;
    load::loadScene(world, "builtin:showcase");
    bool glossy = false, mirror = false, masked = false, glass = false;
    for (const Material& m : world.materials()) {
        glossy |= m.roughness > 0.f && m.roughness <= 0.3f;
        mirror |= m.metallic == 1.f && m.roughness == 0.f;
        masked |= m.alphaMode == AlphaMode::Mask && m.baseColorTexture != kNoTexture;
        glass |= m.transmission > 0.f;
    }
    EXPECT_TRUE(glossy);
    EXPECT_TRUE(mirror);
    EXPECT_TRUE(masked);
    EXPECT_TRUE(glass);
    int rect = 0, point = 0;
    world.each<Light>([&](Entity, const Light& l) {
        rect += l.type == LightType::Rect;
        point += l.type == LightType::Point;
    });
    EXPECT_EQ(rect, 1);
    EXPECT_GE(point, 2);
    EXPECT_EQ(world.count<Volume>(), 1u);
    ASSERT_EQ(world.volumeGrids().size(), 1u);
    EXPECT_GT(world.volumeGrids()[0]->activeVoxelCount(), 0u);
    EXPECT_TRUE(world.alive(world.activeCamera()));
    EXPECT_GT(world.animationDuration(), 0.f);
}

TEST(BuiltinScenes, ShowcaseMovesOneInstanceAndRefitsOneMeshAfterFrameOne) {
    World world;
    load::loadScene(world, "builtin:showcase");
    const FrameUpdate first = world.update(0.f);
    EXPECT_EQ(first.rebuiltMeshes.size(), world.meshes().size());
    for (int frame = 1; frame < 3; ++frame) {
        const FrameUpdate u = world.update(world.settings().frameSeconds);
        EXPECT_EQ(u.movedInstances.size(), 1u) << "frame " << frame;
        EXPECT_EQ(u.refitMeshes.size(), 1u) << "frame " << frame;
        EXPECT_TRUE(u.rebuiltMeshes.empty()) << "frame " << frame;
        EXPECT_FALSE(u.instanceSetChanged) << "frame " << frame;
        ASSERT_EQ(u.movedInstances.size(), 1u);
        EXPECT_EQ(world.get<Name>(u.movedInstances[0])->value, "moving box");
        EXPECT_EQ(world.mesh(u.refitMeshes[0]).name, "waving cloth");
    }
}

TEST(BuiltinScenes, CornellIsDiffuseOnlyAndStatic) {
    World world;
    load::loadScene(world, "builtin:cornell");
    for (const Material& m : world.materials()) {
        EXPECT_EQ(m.alphaMode, AlphaMode::Opaque);
        EXPECT_EQ(m.transmission, 0.f);
        EXPECT_GT(m.roughness, 0.3f);
    }
    EXPECT_EQ(world.count<Volume>(), 0u);
    world.update(0.f);
    EXPECT_FALSE(world.update(0.1f).geometryChanged());
    const SceneSnapshot snap = makeSnapshot(world, {});
    EXPECT_EQ(snap.instances.size(), world.count<MeshInstance>());
    ASSERT_EQ(snap.lights.size(), 1u);
    EXPECT_EQ(snap.lights[0].light.type, LightType::Rect);
}

TEST(BuiltinScenes, UnknownNameAndSourceAreInputErrors) {
    World world;
    EXPECT_THROW(load::loadScene(world, "builtin:nope"), InputError);
    EXPECT_THROW(load::loadScene(world, "/nonexistent/scene.gltf"), InputError);
    EXPECT_THROW(load::loadScene(world, RTLAB_SOURCE_DIR "/CMakeLists.txt"), InputError);
}
