// rtlab in a user's own GoogleTest suite: load a glTF (scene.gltf: a unit
// cube on a ground quad), trace rays through the DXR-style pipeline and
// assert what they hit, down to a golden hash of a whole image. Results are
// bit-reproducible (any thread count, either back end), so exact asserts hold.
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

using namespace rtlab;

namespace {

// What the closest-hit shader reports.
struct HitRecord {
    bool hit = false;
    float t = 0.f;
    std::string mesh;
    std::uint32_t primitive = 0;
};

class SceneTest : public ::testing::Test {
protected:
    void SetUp() override {
        ecs::load::loadGltf(world_, SCENE_GLTF);
        scene_ = ecs::makeSnapshot(world_, world_.update(0.f));
        accel_.update(scene_);
        desc_.hitGroups.resize(accel_.geometrySlotCount());
        for (auto& group : desc_.hitGroups)
            group.closestHit = [this](const tracer::HitContext& c, HitRecord& r, const tracer::HitAttributes&) {
                r = {true, c.rayTCurrent, world_.mesh(c.instance->mesh).name, c.primitiveIndex};
            };
        desc_.missShaders.push_back([](const tracer::MissContext&, HitRecord& r) { r.hit = false; });
    }

    HitRecord trace(const tracer::Pipeline<HitRecord>& pipeline, vec3 origin, vec3 direction) const {
        HitRecord r;
        pipeline.traceRay(tracer::TraceArgs{}, tracer::RayDesc{origin, 0.f, direction, kInfinity}, r);
        return r;
    }

    // A 64x64 view from (3, 2, 4) towards the cube; per pixel the mesh, the
    // primitive and the distance in 1/1024 units, hashed (FNV-1a).
    std::uint64_t imageHash(const tracer::Pipeline<HitRecord>& pipeline) const {
        const int size = 64;
        const vec3 eye(3.f, 2.f, 4.f), forward = glm::normalize(-eye);
        const vec3 right = glm::normalize(glm::cross(forward, vec3(0, 1, 0))), up = glm::cross(right, forward);
        std::vector<std::uint32_t> pixels(size * size);
        pipeline.dispatchRays(size, size, [&](int x, int y) {
            const float u = (x + 0.5f) / size * 2.f - 1.f, v = 1.f - (y + 0.5f) / size * 2.f;
            const HitRecord r = trace(pipeline, eye, glm::normalize(forward + 0.5f * (u * right + v * up)));
            pixels[y * size + x] = r.hit ? (r.mesh == "Cube" ? 1u << 28 : 2u << 28) | r.primitive << 20 |
                                               static_cast<std::uint32_t>(r.t * 1024.f)
                                         : 0u;
        });
        std::uint64_t h = 1469598103934665603ull;
        for (std::uint32_t p : pixels)
            for (int b = 0; b < 4; ++b) h = (h ^ ((p >> (8 * b)) & 0xffu)) * 1099511628211ull;
        return h;
    }

    ecs::World world_;
    ecs::SceneSnapshot scene_;
    tracer::AccelManager accel_;
    tracer::Pipeline<HitRecord>::Desc desc_;
};

// Computed once with rtlab and kept: any change to what these rays hit fails the test.
constexpr std::uint64_t kGoldenImageHash = 0xfb51b2dc4bc8e5d6ull;

TEST_F(SceneTest, LoadsTheCubeAndTheGround) {
    EXPECT_EQ(world_.meshes().size(), 2u);
    EXPECT_EQ(world_.mesh(0).triangleCount() + world_.mesh(1).triangleCount(), 14u);
}

TEST_F(SceneTest, RaysHitWhatTheyShould) {
    const tracer::Pipeline<HitRecord> pipeline(accel_, desc_);
    const HitRecord front = trace(pipeline, vec3(0.1f, 0.2f, 5.f), vec3(0, 0, -1));
    ASSERT_TRUE(front.hit);
    EXPECT_EQ(front.mesh, "Cube");
    EXPECT_FLOAT_EQ(front.t, 4.5f);  // the face at z = 0.5
    const HitRecord ground = trace(pipeline, vec3(1.5f, 3.f, 1.5f), vec3(0, -1, 0));
    ASSERT_TRUE(ground.hit);
    EXPECT_EQ(ground.mesh, "Ground");
    EXPECT_FLOAT_EQ(ground.t, 3.5f);
    EXPECT_FALSE(trace(pipeline, vec3(0.f, 3.f, 0.f), vec3(0, 1, 0)).hit);  // up into the sky
}

TEST_F(SceneTest, GoldenImageHash) {
    const tracer::Pipeline<HitRecord> pipeline(accel_, desc_);
    EXPECT_EQ(imageHash(pipeline), kGoldenImageHash) << std::hex << "hash 0x" << imageHash(pipeline);
}

TEST_F(SceneTest, TheRtCoreModelTracesTheSameImage) {
    rtcore_sim::RtCoreBackend model(rtcore_sim::RtCoreConfig{});
    model.update(scene_);
    model.beginFrame();
    const tracer::Pipeline<HitRecord> pipeline(accel_, desc_, &model);
    EXPECT_EQ(imageHash(pipeline), kGoldenImageHash);
    EXPECT_GT(model.statsJson()["frame"]["cycles"].get<std::uint64_t>(), 0u);
}

}  // namespace
