// AO contact sampling (RenderSettings::aoContactExtraSamples): pixels next
// to a contact get more AO samples, the others keep exactly their spp
// samples, the estimate stays unbiased, and the crease's error falls.
// Scene: a unit box resting on a grey floor, seen from above at an angle.
#include "../../shaders_cpp/src/passes/passes.hpp"

#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/shaders_cpp/frame_plan.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>
#include <rtlab/tracer/accel_manager.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

using namespace rtlab;
using namespace rtlab::shaders;

namespace {

constexpr int kWidth = 40, kHeight = 30;

// A world rendered with the AO pass alone at kWidth x kHeight.
struct AoOnly {
    ecs::World world;
    ecs::SceneSnapshot scene;
    tracer::AccelManager accel;
    FramePlan plan;

    // After the world is built: its snapshot, acceleration structures and plan.
    void prepare() {
        scene = ecs::makeSnapshot(world, world.update(0.f));
        accel.update(scene);
        PlanOptions options;
        options.requested = {Pass::AmbientOcclusion};
        plan = planFrame(scene, options);
    }

    FrameOutput render(int contactSamples, std::uint32_t frame, int spp = 1) {
        RenderSettings s;
        s.width = kWidth;
        s.height = kHeight;
        s.spp = spp;
        s.frame = frame;
        s.aoRadius = 1.f;
        s.aoContactExtraSamples = contactSamples;
        return renderFrame(accel, scene, plan, s);
    }
};

struct BoxOnFloor : AoOnly {
    BoxOnFloor() {
        ecs::Material grey;
        grey.baseColor = vec4(0.5f, 0.5f, 0.5f, 1.f);
        const ecs::MaterialId m = world.addMaterial(grey);
        const auto place = [&](ecs::Geometry g, const vec3& at) {
            const ecs::Entity e = world.create();
            world.emplace(e, ecs::LocalTransform{at, quat(1, 0, 0, 0), vec3(1.f)});
            world.emplace(e, ecs::MeshInstance{world.addMesh(ecs::load::makeMesh("part", std::move(g)))});
        };
        place(ecs::load::makeGrid(40.f, 1, m), vec3(0.f));
        place(ecs::load::makeBox(vec3(1.f), m), vec3(0.f, 0.5f, 0.f));
        const ecs::Entity camera = world.create("camera");
        const vec3 eye(2.2f, 1.8f, 2.6f), target(0.f, 0.3f, 0.f);
        world.emplace(camera, ecs::LocalTransform{eye, orientationLookingAlong(target - eye), vec3(1.f)});
        world.emplace(camera, ecs::Camera{0.9f, 0.01f, 1000.f, 0.f});
        world.setActiveCamera(camera);
        prepare();
    }
};

std::vector<float> channel(const FrameOutput& f, const char* name) {
    const float* c = f.image.channel(name);
    return std::vector<float>(c, c + f.image.pixelCount());
}

std::uint64_t aoRays(const FrameOutput& f) { return f.counters.rays[kRayOcclusion]; }

}  // namespace

// With contact sampling off every geometry pixel traces spp rays; on, only
// some pixels get more, and every other pixel's estimate is bit-identical to
// the uniform render (the extra samples come after the spp ones in the
// random stream).
TEST(AoContactSampling, OnlyPixelsNearAContactGetMoreSamples) {
    BoxOnFloor s;
    const FrameOutput uniform = s.render(0, 0);
    const FrameOutput contact = s.render(8, 0);
    const std::uint64_t base = aoRays(uniform);
    ASSERT_GT(base, static_cast<std::uint64_t>(kWidth * kHeight / 2));  // the floor, the box and some sky
    EXPECT_EQ(aoRays(s.render(0, 0, 2)), 2 * base);
    ASSERT_GT(aoRays(contact), base);
    const std::uint64_t extra = aoRays(contact) - base;
    const std::vector<float> vU = channel(uniform, "ao.V"), vC = channel(contact, "ao.V");
    const std::vector<float> tU = channel(uniform, "ao.hitT"), tC = channel(contact, "ao.hitT");
    std::uint64_t differing = 0;
    for (std::size_t i = 0; i < vU.size(); ++i) differing += vU[i] != vC[i] || tU[i] != tC[i];
    EXPECT_GT(differing, 0u);
    EXPECT_LE(differing, extra);
    EXPECT_LT(differing, base / 2) << "most of the floor is open";
}

// The mean of many frames with contact sampling matches the uniform one's,
// over the crease (pixels a 256-spp render puts below 0.75) and over the
// whole image: the number of samples a pixel gets never depends on its own
// samples. Tolerance: 4 standard errors of the difference, from the frames'
// own spread.
TEST(AoContactSampling, IsUnbiased) {
    BoxOnFloor s;
    constexpr int kFrames = 384;
    const std::size_t n = static_cast<std::size_t>(kWidth * kHeight);
    std::vector<double> sumU(n, 0.0), sumC(n, 0.0);
    std::vector<double> frameCreaseU, frameCreaseC, frameAllU, frameAllC;
    std::vector<std::vector<float>> framesU, framesC;
    for (int f = 0; f < kFrames; ++f) {
        framesU.push_back(channel(s.render(0, static_cast<std::uint32_t>(f)), "ao.V"));
        framesC.push_back(channel(s.render(8, static_cast<std::uint32_t>(1000 + f)), "ao.V"));
        for (std::size_t i = 0; i < n; ++i) sumU[i] += framesU.back()[i], sumC[i] += framesC.back()[i];
    }
    // The crease from an independent render (picked from the uniform frames
    // themselves, it would favour their dark draws).
    const std::vector<float> reference = channel(s.render(0, 7777, 256), "ao.V");
    std::vector<bool> crease(n);
    std::size_t creasePixels = 0;
    for (std::size_t i = 0; i < n; ++i) creasePixels += crease[i] = reference[i] < 0.75f;
    ASSERT_GT(creasePixels, 20u);
    // Per frame: the mean over the crease and over the image, for each method.
    const auto regionMeans = [&](const std::vector<std::vector<float>>& frames, bool creaseOnly) {
        std::vector<double> m;
        for (const auto& v : frames) {
            double sum = 0.0;
            std::size_t count = 0;
            for (std::size_t i = 0; i < n; ++i)
                if (!creaseOnly || crease[i]) sum += v[i], ++count;
            m.push_back(sum / double(count));
        }
        return m;
    };
    const auto meanAndStdError = [](const std::vector<double>& x) {
        double mean = 0.0, var = 0.0;
        for (const double v : x) mean += v;
        mean /= double(x.size());
        for (const double v : x) var += (v - mean) * (v - mean);
        var /= double(x.size() - 1);
        return std::pair<double, double>(mean, std::sqrt(var / double(x.size())));
    };
    for (const bool creaseOnly : {true, false}) {
        const auto [mu, eu] = meanAndStdError(regionMeans(framesU, creaseOnly));
        const auto [mc, ec] = meanAndStdError(regionMeans(framesC, creaseOnly));
        const double tolerance = 4.0 * std::sqrt(eu * eu + ec * ec);
        EXPECT_NEAR(mc, mu, tolerance) << (creaseOnly ? "crease" : "image") << ": uniform " << mu << ", contact " << mc;
        EXPECT_LT(tolerance, 0.02) << "the test must be able to see a bias";
    }
}

// The crease's mean squared error of one 1-spp frame against a 512-spp
// reference falls by half or more (measured: about a seventh), averaged over 16 frames.
TEST(AoContactSampling, LowersTheCreaseError) {
    BoxOnFloor s;
    const std::vector<float> reference = channel(s.render(0, 7777, 512), "ao.V");
    double errorU = 0.0, errorC = 0.0;
    std::size_t count = 0;
    for (int f = 0; f < 16; ++f) {
        const std::vector<float> u = channel(s.render(0, static_cast<std::uint32_t>(f)), "ao.V");
        const std::vector<float> c = channel(s.render(8, static_cast<std::uint32_t>(f)), "ao.V");
        for (std::size_t i = 0; i < reference.size(); ++i) {
            if (!(reference[i] < 0.75f)) continue;
            errorU += (u[i] - reference[i]) * (u[i] - reference[i]);
            errorC += (c[i] - reference[i]) * (c[i] - reference[i]);
            ++count;
        }
    }
    ASSERT_GT(count, 16u * 20u);
    EXPECT_LT(errorC, 0.5 * errorU) << "uniform " << errorU / count << ", contact " << errorC / count;
}

// Which pixels get contact samples, literally: one pixel saw a near
// occluder; every other geometry pixel within 2 pixels of it gets
// perSample, the pixel itself none (its own samples must not decide its
// count), nor do pixels 3 away, a sky pixel, or anyone when the occluder is
// not near.
TEST(AoContactSampling, NeighboursOfANearOccluderButNotThePixelItself) {
    constexpr int w = 9, h = 7;
    std::vector<float> distance(w * h, kInfinity);
    std::vector<std::uint8_t> geometry(w * h, 1);
    const auto at = [&](int x, int y) { return static_cast<std::size_t>(y * w + x); };
    distance[at(4, 3)] = 0.1f;
    geometry[at(5, 4)] = 0;  // sky
    const std::vector<std::uint32_t> counts = detail::aoContactSampleCounts(w, h, distance, geometry, 0.25f, 8, 1000);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const bool inWindow =
                std::abs(x - 4) <= detail::kAoContactWindow && std::abs(y - 3) <= detail::kAoContactWindow;
            const bool expected = inWindow && !(x == 4 && y == 3) && geometry[at(x, y)];
            EXPECT_EQ(counts[at(x, y)], expected ? 8u : 0u) << x << ", " << y;
        }
    // Not nearer than the threshold: nobody.
    for (const std::uint32_t c : detail::aoContactSampleCounts(w, h, distance, geometry, 0.1f, 8, 1000))
        EXPECT_EQ(c, 0u);
    // Mismatched buffers are an error, not a silent empty answer.
    EXPECT_THROW(detail::aoContactSampleCounts(w, h + 1, distance, geometry, 0.25f, 8, 1000), std::invalid_argument);
}

// The budget, literally: on a 12 x 12 image every pixel a source (all 144
// flagged), budget 2 per pixel: each count is 2 x 144 / (144 - c_i + 24)
// rounded down (c_i: pixels only it flags, none here) = 1, and the counts
// sum to at most 2 x 144. A pixel's own samples do not move its count: the
// same answer when one pixel's samples saw nothing near.
TEST(AoContactSampling, TheBudgetSplitsEvenlyAndIgnoresThePixelsOwnSamples) {
    constexpr int w = 12, h = 12;
    std::vector<float> distance(w * h, 0.1f);
    const std::vector<std::uint8_t> geometry(w * h, 1);
    const std::vector<std::uint32_t> counts = detail::aoContactSampleCounts(w, h, distance, geometry, 0.25f, 8, 2);
    std::uint64_t sum = 0;
    for (const std::uint32_t c : counts) {
        EXPECT_EQ(c, 1u);
        sum += c;
    }
    EXPECT_LE(sum, 2u * w * h);
    // Two neighbouring sources, P = (5, 5) and (6, 5), budget 1 (it binds:
    // about 30 of 144 pixels flagged): P is flagged through (6, 5) either
    // way, and its count is the same whether or not its own samples saw a
    // near occluder.
    std::vector<float> sparse(w * h, kInfinity);
    const std::size_t p = 5 * w + 5;
    sparse[p] = 0.1f;
    sparse[5 * w + 6] = 0.1f;
    const std::vector<std::uint32_t> near = detail::aoContactSampleCounts(w, h, sparse, geometry, 0.25f, 8, 1);
    sparse[p] = kInfinity;
    const std::vector<std::uint32_t> far = detail::aoContactSampleCounts(w, h, sparse, geometry, 0.25f, 8, 1);
    EXPECT_GT(near[p], 0u);
    EXPECT_LT(near[p], 8u) << "the budget binds";
    EXPECT_EQ(near[p], far[p]) << "P's count moved with its own samples";
}

// Where contacts are everywhere (the slivers: nearly every pixel flagged) the
// extra rays stay within the budget: AO traces at most three times its
// uniform rays, and still more than them.
TEST(AoContactSampling, ExtraRaysStayWithinTheBudget) {
    AoOnly slivers;
    ecs::load::loadScene(slivers.world, "builtin:slivers?triangles=20000");
    slivers.prepare();
    const std::uint64_t uniform = aoRays(slivers.render(0, 0));
    const std::uint64_t contact = aoRays(slivers.render(8, 0));
    const std::uint64_t more = aoRays(slivers.render(16, 0));
    ASSERT_GT(uniform, 100u);
    EXPECT_GT(contact, uniform);
    EXPECT_LE(contact, 3 * uniform);
    EXPECT_EQ(more, contact) << "the budget binds: asking for more changes nothing";
}
