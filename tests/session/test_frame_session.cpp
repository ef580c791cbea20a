// The frame driver: the same frames as the stages called by hand, every
// option reaching the render settings, and the errors of its options.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/session/frame_session.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <gtest/gtest.h>

namespace rtlab::session {
namespace {

FrameOptions small(const std::string& scene) {
    FrameOptions o;
    o.scene = scene;
    o.width = 48;
    o.height = 27;
    o.denoise = "none";
    return o;
}

// Two frames of a scene through the session and through the stages by hand
// (world update, snapshot, Embree, plan, renderFrame with a shared history):
// bit-identical images, the same plan and counters.
::testing::AssertionResult sameAsStages(const FrameOptions& o) {
    FrameSession session(o);
    session.load();
    ecs::World world;
    ecs::load::loadScene(world, o.scene);
    tracer::AccelManager accel;
    shaders::FrameHistory history;
    for (std::uint32_t f = 0; f < 2; ++f) {
        const FrameState& state = session.advance();
        const shaders::FrameOutput viaSession = session.render();

        const ecs::FrameUpdate update = world.update(f == 0 ? 0.f : world.settings().frameSeconds);
        const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, update);
        accel.update(scene);
        const shaders::FramePlan plan = shaders::planFrame(scene, o.planOptions());
        shaders::RenderSettings settings;
        settings.width = o.width;
        settings.height = o.height;
        settings.frame = f;
        const shaders::FrameOutput byHand = shaders::renderFrame(accel, scene, plan, settings, history);

        const std::string where = o.scene + " frame " + std::to_string(f);
        if (state.index != f) return ::testing::AssertionFailure() << where << ": index " << state.index;
        if (state.plan.toJson() != plan.toJson()) return ::testing::AssertionFailure() << where << ": plans differ";
        if (!compareImages(viaSession.image, byHand.image).identical)
            return ::testing::AssertionFailure() << where << ": images differ";
        if (viaSession.counters.totalRays() != byHand.counters.totalRays())
            return ::testing::AssertionFailure() << where << ": " << viaSession.counters.totalRays()
                                                 << " rays, by hand " << byHand.counters.totalRays();
    }
    return ::testing::AssertionSuccess();
}

TEST(FrameSession, ShowcaseFramesEqualTheStagesByHand) { EXPECT_TRUE(sameAsStages(small("builtin:showcase"))); }
TEST(FrameSession, ForestFramesEqualTheStagesByHand) {
    EXPECT_TRUE(sameAsStages(small("builtin:forest?instances=20")));
}

TEST(FrameSession, EveryOptionReachesTheRenderSettings) {
    FrameOptions o = small("builtin:cornell");
    o.spp = 3;
    o.seed = 9;
    o.aoRadius = 0.5f;
    o.aoContactSamples = 2;
    o.maxTranslucencyDepth = 5;
    o.maxDepth = 7;
    FrameSession session(o);
    session.load();
    session.advance();
    session.advance();
    const shaders::RenderSettings s = session.renderSettings();
    EXPECT_EQ(s.width, 48);
    EXPECT_EQ(s.height, 27);
    EXPECT_EQ(s.spp, 3);
    EXPECT_EQ(s.seed, 9u);
    EXPECT_EQ(s.frame, 1u);
    EXPECT_EQ(s.aoRadius, 0.5f);
    EXPECT_EQ(s.aoContactExtraSamples, 2);
    EXPECT_EQ(s.maxTranslucencyDepth, 5);
    EXPECT_EQ(s.pathMaxDepth, 7);
    EXPECT_EQ(s.backend, nullptr);
    EXPECT_FALSE(s.recordRayOrder);
}

TEST(FrameSession, RtCoreBackendIsTheModel) {
    FrameOptions o = small("builtin:cornell");
    o.backend = "rtcore";
    o.rtcoreSet = {"gpu.cores=2"};
    FrameSession session(o);
    ASSERT_NE(session.rtcore(), nullptr);
    session.load();
    session.advance();
    EXPECT_EQ(session.renderSettings().backend, static_cast<tracer::TraversalBackend*>(session.rtcore()));
    EXPECT_GT(session.render().counters.totalRays(), 0u);
}

TEST(FrameSession, BadOptionsAreInputErrorsBeforeLoading) {
    FrameOptions o = small("builtin:no-such-scene");
    o.effects = "glitter";
    EXPECT_THROW(FrameSession{o}, InputError);  // before the scene (which is bad too) is touched
    o.effects = "auto";
    o.denoise = "glitter";
    EXPECT_THROW(FrameSession{o}, InputError);
    o.denoise = "none";
    o.verify = true;
    EXPECT_THROW(FrameSession{o}, InputError);
    o.verify = false;
    FrameSession session(o);
    EXPECT_THROW(session.load(), InputError);
}

TEST(FrameSession, RenderSettingsValidateThemselves) {
    shaders::RenderSettings s;
    s.spp = 0;
    EXPECT_THROW(s.validate(), std::invalid_argument);
    s.spp = 1;
    s.pathMaxDepth = -1;
    EXPECT_THROW(s.validate(), std::invalid_argument);
    s.pathMaxDepth = 0;
    EXPECT_NO_THROW(s.validate());
}

}  // namespace
}  // namespace rtlab::session
