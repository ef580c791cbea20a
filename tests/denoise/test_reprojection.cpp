// Guide buffers, depth gradient and reprojection with consistency checks.
#include "denoise/denoise_test_util.hpp"

#include <rtlab/denoise/reprojection.hpp>

#include <gtest/gtest.h>

#include <stdexcept>

using namespace rtlab;
using namespace rtlab::denoise;
using namespace rtlab::denoise::testing;

namespace {

std::size_t idx(const GuideBuffers& g, int x, int y) { return static_cast<std::size_t>(y) * g.width + x; }

}  // namespace

TEST(DenoiseGuides, DepthGradientOfAPlaneIsItsSlope) {
    GuideBuffers g(9, 7);
    for (int y = 0; y < g.height; ++y)
        for (int x = 0; x < g.width; ++x) g.depth[idx(g, x, y)] = 2.f + 0.25f * x - 0.125f * y;
    const std::vector<vec2> grad = depthGradient(g);
    for (const vec2& d : grad) {
        EXPECT_FLOAT_EQ(d.x, 0.25f);
        EXPECT_FLOAT_EQ(d.y, -0.125f);
    }
}

TEST(DenoiseGuides, DepthGradientIgnoresTheOtherSideOfAnEdge) {
    // Left half: plane of slope 0.25 at depth ~1; right half: depth 10 (a step).
    GuideBuffers g(8, 4);
    for (int y = 0; y < g.height; ++y)
        for (int x = 0; x < g.width; ++x) g.depth[idx(g, x, y)] = x < 4 ? 1.f + 0.25f * x : 10.f;
    const std::vector<vec2> grad = depthGradient(g);
    // Pixels beside the step keep the slope of their own side: the step (~8)
    // would make the depth tests accept anything.
    EXPECT_FLOAT_EQ(grad[idx(g, 3, 1)].x, 0.25f);
    EXPECT_FLOAT_EQ(grad[idx(g, 4, 1)].x, 0.f);
    // A different mesh id on the other side: its neighbour is not used at all.
    g.meshId.assign(g.pixelCount(), 0);
    for (int y = 0; y < g.height; ++y) g.meshId[idx(g, 4, y)] = 1;
    g.depth[idx(g, 4, 1)] = g.depth[idx(g, 3, 1)] + 100.f;
    EXPECT_FLOAT_EQ(depthGradient(g)[idx(g, 3, 1)].x, 0.25f);
}

TEST(DenoiseGuides, ValidateRejectsMismatchedBuffers) {
    GuideBuffers g(4, 4);
    EXPECT_NO_THROW(g.validate());
    g.normal.pop_back();
    EXPECT_THROW(g.validate(), std::invalid_argument);
}

TEST(DenoiseReprojection, StaticPixelsReprojectOntoThemselves) {
    const GuideBuffers g = flatGuides(6, 5);
    const Reprojection r = reproject(g, g);
    ASSERT_EQ(r.validCount(), g.pixelCount());
    for (std::size_t i = 0; i < g.pixelCount(); ++i) {
        EXPECT_EQ(r.taps[i].index[0], i);
        EXPECT_EQ(r.taps[i].weight[0], 1.f);
        EXPECT_EQ(r.taps[i].weight[1] + r.taps[i].weight[2] + r.taps[i].weight[3], 0.f);
    }
    // A constant buffer gathers to exactly the same constant.
    std::vector<vec3> prev(g.pixelCount(), vec3(0.37f, 1.5f, 1e4f)), out(g.pixelCount());
    gather(r, std::span<const vec3>(prev), std::span<vec3>(out));
    for (const vec3& c : out) EXPECT_EQ(c, vec3(0.37f, 1.5f, 1e4f));
}

TEST(DenoiseReprojection, HalfPixelMotionIsABilinearGather) {
    GuideBuffers g = flatGuides(6, 6);
    g.motion.assign(g.pixelCount(), vec2(0.5f, 0.5f));
    std::vector<float> prev(g.pixelCount());
    for (std::size_t i = 0; i < prev.size(); ++i) prev[i] = static_cast<float>(i);
    const Reprojection r = reproject(g, g);
    std::vector<float> out(g.pixelCount());
    gather(r, std::span<const float>(prev), std::span<float>(out), -1.f);
    // Interior pixel (2,2): the mean of pixels (2,2),(3,2),(2,3),(3,3).
    const std::size_t i = idx(g, 2, 2);
    ASSERT_TRUE(r.valid[i]);
    for (int k = 0; k < 4; ++k) EXPECT_FLOAT_EQ(r.taps[i].weight[k], 0.25f);
    EXPECT_FLOAT_EQ(out[i],
                    0.25f * (prev[idx(g, 2, 2)] + prev[idx(g, 3, 2)] + prev[idx(g, 2, 3)] + prev[idx(g, 3, 3)]));
    // Right column: the previous centre x = 5.9 is on screen, the right taps
    // are not -> renormalised over the left two.
    const std::size_t e = idx(g, 5, 2);
    g.motion[e] = vec2(0.4f, 0.5f);
    const Reprojection re = reproject(g, g);
    ASSERT_TRUE(re.valid[e]);
    gather(re, std::span<const float>(prev), std::span<float>(out), -1.f);
    EXPECT_FLOAT_EQ(out[e], 0.5f * (prev[idx(g, 5, 2)] + prev[idx(g, 5, 3)]));
    // ...while x = 6.0 is off screen: no history.
    EXPECT_FALSE(r.valid[e]);
}

TEST(DenoiseReprojection, FailingTapsAreDroppedAndTheRestRenormalised) {
    GuideBuffers cur = flatGuides(6, 6);
    cur.motion.assign(cur.pixelCount(), vec2(0.5f, 0.5f));
    GuideBuffers prev = flatGuides(6, 6);
    prev.meshId[idx(prev, 3, 3)] = 5;  // one of the four taps of pixel (2,2) is another object
    const Reprojection r = reproject(cur, prev);
    const std::size_t i = idx(cur, 2, 2);
    ASSERT_TRUE(r.valid[i]);
    std::vector<float> hist(cur.pixelCount(), 0.f);
    hist[idx(cur, 2, 2)] = 3.f;
    hist[idx(cur, 3, 2)] = 6.f;
    hist[idx(cur, 2, 3)] = 9.f;
    hist[idx(cur, 3, 3)] = 1000.f;  // must not leak in
    std::vector<float> out(cur.pixelCount());
    gather(r, std::span<const float>(hist), std::span<float>(out));
    EXPECT_NEAR(out[i], 6.f, 1e-5f);
}

TEST(DenoiseReprojection, ConsistencyChecksRejectDisocclusions) {
    const GuideBuffers prev = flatGuides(8, 8);
    const std::size_t p = idx(prev, 4, 4);

    GuideBuffers cur = flatGuides(8, 8);
    EXPECT_TRUE(reproject(cur, prev).valid[p]);

    cur = flatGuides(8, 8);
    cur.meshId[p] = 3;  // another object now covers this pixel
    EXPECT_FALSE(reproject(cur, prev).valid[p]);

    cur = flatGuides(8, 8);
    cur.depth.assign(cur.pixelCount(), 1.5f);  // flat: 0.5 > 10 * (0 + 0.01)
    EXPECT_FALSE(reproject(cur, prev).valid[p]);
    cur.depth.assign(cur.pixelCount(), 1.05f);  // within 10 * 0.01
    EXPECT_TRUE(reproject(cur, prev).valid[p]);

    cur = flatGuides(8, 8);
    cur.normal[p] = glm::normalize(vec3(1.f, 0.f, 1.f));  // 45 deg: dot 0.707 < 0.9
    EXPECT_FALSE(reproject(cur, prev).valid[p]);
    cur.normal[p] = glm::normalize(vec3(0.2f, 0.f, 1.f));  // dot 0.98
    EXPECT_TRUE(reproject(cur, prev).valid[p]);

    cur = flatGuides(8, 8);
    cur.motion[p] = vec2(-4.6f, 0.f);  // previous centre at x = -0.1: off screen
    EXPECT_FALSE(reproject(cur, prev).valid[p]);
    cur.motion[p] = vec2(0.f, 3.6f);  // previous centre at y = 8.1: off screen
    EXPECT_FALSE(reproject(cur, prev).valid[p]);
    cur.motion[p] = vec2(-4.4f, 0.f);  // x = 0.1: on screen
    EXPECT_TRUE(reproject(cur, prev).valid[p]);
    cur.motion[p] = vec2(1e30f, -1e30f);  // absurd but finite
    EXPECT_FALSE(reproject(cur, prev).valid[p]);
}

TEST(DenoiseReprojection, SlopedSurfacesPassTheDepthTestThroughTheirGradient) {
    // A steep plane (slope 1 per pixel) moving by one pixel: the depth at the
    // previous position differs by the slope, which fwidth(z) tolerates.
    GuideBuffers prev(10, 4), cur(10, 4);
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 10; ++x) {
            prev.depth[idx(prev, x, y)] = 10.f + x;
            cur.depth[idx(cur, x, y)] = 10.f + x + 1.f;  // moved one pixel right...
            cur.motion[idx(cur, x, y)] = vec2(0.f);      // ...but motion says static
        }
    EXPECT_EQ(reproject(cur, prev).validCount(), cur.pixelCount());
    // The same depth difference on a fronto-parallel plane is a disocclusion.
    GuideBuffers flatPrev(10, 4), flatCur(10, 4);
    flatPrev.depth.assign(flatPrev.pixelCount(), 10.f);
    flatCur.depth.assign(flatCur.pixelCount(), 11.f);
    EXPECT_EQ(reproject(flatCur, flatPrev).validCount(), 0u);
}

TEST(DenoiseReprojection, SkyMatchesSkyOnMeshIdAlone) {
    GuideBuffers prev = flatGuides(4, 4), cur = flatGuides(4, 4);
    prev.meshId.assign(prev.pixelCount(), -1);
    cur.meshId.assign(cur.pixelCount(), -1);
    prev.depth.assign(prev.pixelCount(), kInfinity);  // sky depth is ignored
    cur.depth.assign(cur.pixelCount(), 0.f);
    EXPECT_EQ(reproject(cur, prev).validCount(), cur.pixelCount());
    cur.meshId[0] = 2;
    EXPECT_FALSE(reproject(cur, prev).valid[0]);
}

TEST(DenoiseReprojection, SizeMismatchThrows) {
    EXPECT_THROW(reproject(flatGuides(4, 4), flatGuides(4, 5)), std::invalid_argument);
    const Reprojection r = reproject(flatGuides(4, 4), flatGuides(4, 4));
    std::vector<float> prev(15), out(16);
    EXPECT_THROW(gather(r, std::span<const float>(prev), std::span<float>(out)), std::invalid_argument);
}
