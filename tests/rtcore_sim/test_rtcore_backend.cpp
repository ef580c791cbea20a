// The RT-core model behind tracer::Pipeline (rtcore_sim::RtCoreBackend): the
// same shaders and scenes give the same images as Embree, verification
// compares every ray, statistics and per-ray records cover the frame, and
// everything is identical across thread counts. (The DXR conformance suite
// also runs on this back end: the rtcore_backend.* tests.)
#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/rtcore_sim/scheduler.hpp>
#include <rtlab/shaders_cpp/preview_shading.hpp>
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

using namespace rtlab;
using namespace rtlab::rtcore_sim;

namespace {

const std::filesystem::path kEngine = "/usr/share/assimp/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";

struct Frame {
    shaders::PreviewResult preview;
    nlohmann::json stats;
    VerifyStats verify;
    std::size_t records = 0;
};

// Renders `frames` preview frames of `source` on Embree and on the model;
// returns the last frame of each.
struct BothBackEnds {
    shaders::PreviewResult embree;
    Frame rtcore;
};
BothBackEnds renderBoth(const std::string& source, int frames, int width, int height, const RtCoreConfig& config = {},
                        bool verify = true) {
    ecs::World world;
    ecs::load::loadScene(world, source);
    tracer::AccelManager accel;
    RtCoreBackend backend(config);
    backend.recordPrimaryRays(true);
    backend.setVerify(verify);
    BothBackEnds out;
    for (int f = 0; f < frames; ++f) {
        const ecs::FrameUpdate update = world.update(f == 0 ? 0.f : world.settings().frameSeconds);
        const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, update);
        accel.update(scene);
        backend.update(scene);
        backend.beginFrame();
        out.embree = shaders::renderPreview(accel, scene, {width, height});
        shaders::PreviewSettings settings{width, height, &backend, true};
        out.rtcore.preview = shaders::renderPreview(accel, scene, settings);
        out.rtcore.stats = backend.statsJson();
        out.rtcore.verify = backend.verifyStats();
        out.rtcore.records = backend.primaryRays().size();
    }
    return out;
}

}  // namespace

// Literal cases of the comparison verification uses.
TEST(RtCoreBackend, SameHitRules) {
    tracer::CommittedHit a, b;
    EXPECT_TRUE(sameHit(a, b, false));  // both miss
    a.hit = b.hit = true;
    a.t = 10.f;
    b.t = 10.f * (1.f + 5e-7f);
    EXPECT_TRUE(sameHit(a, b, false));
    b.t = 10.f * (1.f + 3e-6f);
    EXPECT_FALSE(sameHit(a, b, false));  // t beyond 1e-6 relative
    EXPECT_TRUE(sameHit(a, b, true));    // first-hit rays: hit/miss only
    b.t = a.t;
    b.primitiveIndex = 1;
    EXPECT_FALSE(sameHit(a, b, false));
    EXPECT_TRUE(sameHit(a, b, true));
    b.primitiveIndex = 0;
    b.hitKind = 255;  // back face vs front face
    EXPECT_FALSE(sameHit(a, b, false));
    b.hitKind = a.hitKind;
    b.hitGroupRecord = 3;
    EXPECT_FALSE(sameHit(a, b, false));
    b.hit = false;
    EXPECT_FALSE(sameHit(a, b, true));
}

TEST(RtCoreBackend, ShowcaseThreeFramesBitIdenticalToEmbree) {
    const BothBackEnds r = renderBoth("builtin:showcase", 3, 128, 72);
    const ImageDifference d = compareImages(r.rtcore.preview.image, r.embree.image);
    EXPECT_TRUE(d.identical) << "max abs diff " << d.maxAbsDiff;
    EXPECT_EQ(r.rtcore.verify.rays, 128u * 72u);
    EXPECT_EQ(r.rtcore.verify.mismatches, 0u);
    EXPECT_EQ(r.rtcore.verify.notBitIdentical, 0u);
    EXPECT_EQ(r.rtcore.preview.counters.rays[0], r.embree.counters.rays[0]);
    EXPECT_EQ(r.rtcore.preview.counters.hits[0], r.embree.counters.hits[0]);
    // Showcase has alpha-masked foliage: its any-hit shader runs on both.
    EXPECT_GT(r.rtcore.preview.counters.anyHitInvocations, 0u);
    EXPECT_GT(r.rtcore.stats["shader"]["anyHitCalls"].get<std::uint64_t>(), 0u);
}

TEST(RtCoreBackend, CornellBitIdenticalToEmbreeIncludingTies) {
    // The camera sits on the box's symmetry plane: diagonal pixels hit the
    // seams where walls meet at the same t (ties, settled by ids on both).
    const BothBackEnds r = renderBoth("builtin:cornell", 1, 320, 240);
    EXPECT_EQ(r.rtcore.verify.mismatches, 0u);
    EXPECT_TRUE(compareImages(r.rtcore.preview.image, r.embree.image).identical);
}

TEST(RtCoreBackend, ThirdPartyGltfBitIdenticalToEmbree) {
    ASSERT_TRUE(std::filesystem::exists(kEngine)) << "assimp-testmodels missing (scripts/install-deps.sh installs it)";
    const BothBackEnds r = renderBoth(kEngine.string(), 1, 160, 120);
    EXPECT_EQ(r.rtcore.verify.mismatches, 0u);
    EXPECT_TRUE(compareImages(r.rtcore.preview.image, r.embree.image).identical);
}

TEST(RtCoreBackend, FrameStatsAndPrimaryRayRecordsCoverEveryPixel) {
    const int w = 64, h = 40;
    const BothBackEnds r = renderBoth("builtin:showcase", 1, w, h, {}, false);
    const nlohmann::json& s = r.rtcore.stats;
    EXPECT_EQ(s["frame"]["rays"].get<std::uint64_t>(), std::uint64_t(w) * h);
    EXPECT_EQ(s["rays"]["submitted"].get<std::uint64_t>(), s["rays"]["completed"].get<std::uint64_t>());
    EXPECT_GT(s["frame"]["cycles"].get<std::uint64_t>(), 0u);
    EXPECT_EQ(s["config"], RtCoreConfig{}.toJson());
    // One trace call per 16x16 tile: ceil(64/16) x ceil(40/16) = 4 x 3; the
    // preview's dispatch is one launch (launch mode), or a batch per call (tile mode).
    EXPECT_EQ(s["backend"]["traceCalls"].get<std::uint64_t>(), 12u);
    EXPECT_EQ(s["frame"]["batches"].get<std::uint64_t>(), 1u);
    ASSERT_EQ(s["backend"]["launches"].size(), 1u);
    EXPECT_EQ(s["backend"]["launches"][0]["rays"], std::uint64_t(w) * h);
    EXPECT_EQ(s["backend"]["launches"][0]["threads"], std::uint64_t(w) * h);
    EXPECT_EQ(s["backend"]["launches"][0]["cycles"], s["frame"]["cycles"]);
    // Its busiest resource of each kind, each utilization in [0, 1].
    const nlohmann::json& launch = s["backend"]["launches"][0];
    EXPECT_FALSE(launch["busiest"]["resource"].get<std::string>().empty());
    for (const auto& [kind, u] : launch["busiestByKind"].items()) {
        EXPECT_GE(u.get<double>(), 0.0) << kind;
        EXPECT_LE(u.get<double>(), 1.0) << kind;
        EXPECT_LE(u.get<double>(), launch["busiest"]["utilization"].get<double>()) << kind;
    }
    EXPECT_TRUE(launch["busiestByKind"].contains("raySlots"));
    RtCoreConfig tile;
    tile.gpu.launch = LaunchMode::Tile;
    const nlohmann::json t = renderBoth("builtin:showcase", 1, w, h, tile, false).rtcore.stats;
    EXPECT_EQ(t["frame"]["batches"].get<std::uint64_t>(), 12u);
    EXPECT_TRUE(t["backend"]["launches"].empty());
    EXPECT_EQ(t["frame"]["rays"], s["frame"]["rays"]);
    EXPECT_EQ(r.rtcore.records, std::size_t(w) * h);
    ASSERT_EQ(r.rtcore.preview.primaryRayPixels.size(), std::size_t(w) * h);
    // Every pixel exactly once.
    std::vector<int> seen(std::size_t(w) * h, 0);
    for (std::uint32_t p : r.rtcore.preview.primaryRayPixels) ++seen.at(p);
    EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), w * h);
}

TEST(RtCoreBackend, ConfigurationChangesCyclesNotImages) {
    RtCoreConfig scarce;
    scarce.cache.sizeBytes = 4096;
    scarce.memory.latency = 400;
    scarce.scheduler.policy = "oldestFirst";
    const BothBackEnds a = renderBoth("builtin:showcase", 1, 64, 40, {}, false);
    const BothBackEnds b = renderBoth("builtin:showcase", 1, 64, 40, scarce, false);
    EXPECT_TRUE(compareImages(a.rtcore.preview.image, b.rtcore.preview.image).identical);
    EXPECT_GT(b.rtcore.stats["frame"]["cycles"].get<std::uint64_t>(),
              a.rtcore.stats["frame"]["cycles"].get<std::uint64_t>());
    EXPECT_EQ(b.rtcore.stats["config"]["scheduler"]["policy"], "oldestFirst");
}

TEST(RtCoreBackend, IdenticalForOneAndTwoThreads) {
    BothBackEnds one, two;
    {
        const ThreadLimit limit(1);
        one = renderBoth("builtin:showcase", 2, 64, 40, {}, false);
    }
    {
        const ThreadLimit limit(2);
        two = renderBoth("builtin:showcase", 2, 64, 40, {}, false);
    }
    EXPECT_TRUE(compareImages(one.rtcore.preview.image, two.rtcore.preview.image).identical);
    EXPECT_EQ(one.rtcore.stats, two.rtcore.stats);
    EXPECT_EQ(one.rtcore.preview.primaryRayPixels, two.rtcore.preview.primaryRayPixels);
}

// Launch mode lets the pipeline run a launch's calls on several host threads
// (its log's order does not matter); tile mode, verification and recording
// keep them in order on one thread.
TEST(RtCoreBackend, OnlyLaunchModeWithoutVerificationOrRecordingRunsConcurrently) {
    RtCoreBackend launch{RtCoreConfig{}};
    EXPECT_TRUE(launch.launchMode());
    EXPECT_FALSE(launch.orderDependent());
    launch.setVerify(true);
    EXPECT_TRUE(launch.orderDependent());
    launch.setVerify(false);
    launch.keepCallVerdicts(true);
    EXPECT_TRUE(launch.orderDependent());
    RtCoreConfig tileConfig;
    tileConfig.gpu.launch = LaunchMode::Tile;
    EXPECT_TRUE(RtCoreBackend(tileConfig).orderDependent());
}

namespace {

// The Cornell box with Embree's acceleration structures, and the shader
// table of a pipeline whose shaders do nothing (one miss shader).
struct Cornell {
    struct Payload {};
    ecs::World world;
    ecs::SceneSnapshot scene;
    tracer::AccelManager accel;
    Cornell() {
        ecs::load::loadScene(world, "builtin:cornell");
        scene = ecs::makeSnapshot(world, world.update(0.f));
        accel.update(scene);
    }
    static tracer::Pipeline<Payload>::Desc emptyShaders() {
        tracer::Pipeline<Payload>::Desc desc;
        desc.missShaders.push_back([](const tracer::MissContext&, Payload&) {});
        return desc;
    }
};

}  // namespace

// The primary-ray records are in a dispatch's thread order, and
// tilePixelOrder names the pixel of each thread as the pipeline numbers
// them (an image of odd size: edge tiles are smaller).
TEST(RtCoreBackend, TilePixelOrderIsThePipelinesThreadNumbering) {
    const Cornell cornell;
    const tracer::Pipeline<Cornell::Payload> pipeline(cornell.accel, Cornell::emptyShaders());
    const int w = 37, h = 21;
    std::vector<std::uint32_t> pixelOfThread(std::size_t(w) * h, ~0u);
    pipeline.dispatchRays(w, h, [&](int x, int y) {
        pixelOfThread.at(tracer::currentTraceScope().thread) = static_cast<std::uint32_t>(y * w + x);
    });
    EXPECT_EQ(pixelOfThread, tilePixelOrder(w, h));
}

// A dispatch made inside a tile numbers its threads from 0 again: it runs
// on that tile's host thread, so no launch thread's rays reach the model
// from two host threads at once (their order would then depend on timing).
TEST(RtCoreBackend, ADispatchInsideATileRunsOnThatTilesHostThread) {
    const Cornell cornell;
    RtCoreBackend backend{RtCoreConfig{}};
    backend.update(cornell.scene);
    backend.beginFrame();
    ASSERT_FALSE(backend.orderDependent());
    const tracer::Pipeline<Cornell::Payload> pipeline(cornell.accel, Cornell::emptyShaders(), &backend);
    const ThreadLimit limit(2);
    std::atomic<int> inner{0}, foreign{0};
    pipeline.dispatchRays(64, 32, [&](int x, int y) {
        if (x % 16 != 0 || y % 16 != 0) return;  // once per tile
        const std::thread::id outer = std::this_thread::get_id();
        pipeline.dispatchRays(20, 20, [&](int, int) {
            ++inner;
            if (std::this_thread::get_id() != outer) ++foreign;
        });
    });
    EXPECT_EQ(inner.load(), 8 * 400);
    EXPECT_EQ(foreign.load(), 0);
}

TEST(RtCoreBackend, RecordingRayOrderNeedsABackEnd) {
    const Cornell cornell;
    shaders::PreviewSettings settings{16, 16, nullptr, true};
    EXPECT_THROW(shaders::renderPreview(cornell.accel, cornell.scene, settings), std::invalid_argument);
}

namespace {

// Last ready ray first, counting its decisions.
class LifoPolicy final : public SchedulerPolicy {
public:
    static inline std::uint64_t pops = 0;
    void push(const ReadyRay& ray) override { stack_.push_back(ray); }
    bool pop(ReadyRay& out) override {
        if (stack_.empty()) return false;
        out = stack_.back();
        stack_.pop_back();
        ++pops;
        return true;
    }
    std::size_t size() const override { return stack_.size(); }
    bool usesAddress() const override { return false; }

private:
    std::vector<ReadyRay> stack_;
};

}  // namespace

// A scheduling policy registered at run time, from outside the library: the
// configuration accepts its name, the model issues through it, and the hits
// stay Embree's.
TEST(RtCoreBackend, PolicyRegisteredFromOutsideTheLibrary) {
    static const SchedulerPolicyEntry lifo{
        "testLifo", "last ready ray issues first",
        [](const SchedulerParams&) -> std::unique_ptr<SchedulerPolicy> { return std::make_unique<LifoPolicy>(); }};
    static const bool registered = (registerSchedulerPolicy(lifo), true);  // once, even under --gtest_repeat
    ASSERT_TRUE(registered);
    EXPECT_THROW(registerSchedulerPolicy(lifo), std::invalid_argument);
    const std::vector<std::string> names = schedulerPolicyNames();
    EXPECT_NE(std::find(names.begin(), names.end(), "testLifo"), names.end());

    RtCoreConfig config;
    EXPECT_THROW(config.set("scheduler.policy=noSuchPolicy"), InputError);
    config.set("scheduler.policy=testLifo");
    LifoPolicy::pops = 0;
    const BothBackEnds r = renderBoth("builtin:cornell", 1, 64, 48, config);
    EXPECT_GT(LifoPolicy::pops, 0u);
    EXPECT_EQ(r.rtcore.stats["scheduler"]["policy"], "testLifo");
    EXPECT_EQ(r.rtcore.verify.mismatches, 0u);
    EXPECT_TRUE(compareImages(r.rtcore.preview.image, r.embree.image).identical);
}
