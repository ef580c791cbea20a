// Firefly clamp, history clamp, albedo demodulation / remodulation.
#include "denoise/denoise_test_util.hpp"

#include <rtlab/denoise/clamp.hpp>
#include <rtlab/denoise/modulation.hpp>

#include <gtest/gtest.h>

#include <cmath>

using namespace rtlab;
using namespace rtlab::denoise;
using namespace rtlab::denoise::testing;

namespace {

std::vector<vec3> smoothImage(int w, int h) {
    std::vector<vec3> img(static_cast<std::size_t>(w) * h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            img[static_cast<std::size_t>(y) * w + x] =
                vec3(0.5f + 0.3f * std::sin(0.2f * x) * std::cos(0.15f * y), 0.1f + 0.01f * x, 2.f - 0.02f * y);
    return img;
}

}  // namespace

TEST(DenoiseFireflyClamp, RemovesASingleHugeSample) {
    for (const int radius : {1, 2}) {
        const int w = 9, h = 7;
        std::vector<vec3> img = constantImage(static_cast<std::size_t>(w) * h, 1.f);
        img[3 * w + 4] = vec3(1e20f);
        std::vector<vec3> out(img.size());
        FireflyClampParams p;
        p.radius = radius;
        clampFireflies(w, h, img, out, p);
        EXPECT_EQ(out[3 * w + 4], vec3(1.f)) << radius;
        for (std::size_t i = 0; i < img.size(); ++i)
            if (i != static_cast<std::size_t>(3 * w + 4)) {
                EXPECT_EQ(out[i], vec3(1.f)) << i;
            }
    }
}

TEST(DenoiseFireflyClamp, LeavesASmoothImageBitIdentical) {
    const int w = 40, h = 30;
    const std::vector<vec3> img = smoothImage(w, h);
    std::vector<vec3> out(img.size());
    for (const int radius : {1, 2}) {
        FireflyClampParams p;
        p.radius = radius;
        clampFireflies(w, h, img, out, p);
        EXPECT_EQ(out, img) << radius;
    }
    // With k = 0 every pixel is pulled to its neighbours' mean: the test can fail.
    FireflyClampParams zero;
    zero.k = 0.f;
    clampFireflies(w, h, img, out, zero);
    EXPECT_NE(out, img);
}

TEST(DenoiseFireflyClamp, ConstantAndTinyImages) {
    for (const auto& [w, h] : {std::pair{1, 1}, std::pair{3, 2}, std::pair{5, 5}}) {
        const std::vector<vec3> img = constantImage(static_cast<std::size_t>(w) * h, 0.6f);
        std::vector<vec3> out(img.size());
        clampFireflies(w, h, img, out);
        EXPECT_EQ(out, img);
    }
    // 1x1 with a firefly: no neighbours, nothing to compare against, kept (finite).
    std::vector<vec3> one{vec3(1e20f)}, out(1);
    clampFireflies(1, 1, one, out);
    EXPECT_EQ(out[0], vec3(1e20f));
}

TEST(DenoiseHistoryClamp, MinMaxAndMeanSigma) {
    const int w = 5, h = 5;
    std::vector<vec3> current(25);
    for (int i = 0; i < 25; ++i) current[i] = vec3(0.4f + 0.01f * static_cast<float>(i % 3));  // 0.40 .. 0.42
    std::vector<float> length(25, 3.f);

    HistoryClampParams minmax;
    minmax.mode = HistoryClampMode::MinMax;
    std::vector<vec3> history(25, vec3(5.f));  // stale bright history (ghost)
    history[0] = vec3(0.41f);                  // inside the bounds: untouched
    length[24] = 0.f;                          // no history: left alone
    clampHistory(w, h, current, history, length, minmax);
    EXPECT_EQ(history[0], vec3(0.41f));
    EXPECT_FLOAT_EQ(history[12].r, 0.42f);  // 3x3 max
    EXPECT_EQ(history[24], vec3(5.f));

    HistoryClampParams meanSigma;
    meanSigma.mode = HistoryClampMode::MeanSigma;
    meanSigma.k = 1.f;
    std::vector<vec3> h2(25, vec3(-3.f));
    clampHistory(w, h, current, h2, {}, meanSigma);
    // Pixel 12's 3x3 window: values 0.40/0.41/0.42, three of each -> mean 0.41, sigma sqrt(2/3)*0.01.
    EXPECT_NEAR(h2[12].r, 0.41f - std::sqrt(2.f / 3.f) * 0.01f, 1e-6f);

    HistoryClampParams none;
    std::vector<vec3> h3(25, vec3(7.f));
    clampHistory(w, h, current, h3, {}, none);
    EXPECT_EQ(h3[12], vec3(7.f));
}

TEST(DenoiseHistoryClamp, ConstantCurrentPinsHistoryToIt) {
    const std::vector<vec3> current = constantImage(12, 0.25f);
    std::vector<vec3> history = constantImage(12, 0.25f);
    HistoryClampParams p;
    p.mode = HistoryClampMode::MeanSigma;
    clampHistory(4, 3, current, history, {}, p);
    EXPECT_EQ(history, current);
}

TEST(DenoiseModulation, RoundTripAndSafeEpsilon) {
    const std::vector<vec3> color{vec3(0.5f, 0.2f, 0.1f), vec3(1e4f), vec3(0.f), vec3(0.3f)};
    const std::vector<vec3> albedo{vec3(0.5f, 0.25f, 1.f), vec3(0.8f), vec3(0.f), vec3(0.f, -1.f, 1e-9f)};
    std::vector<vec3> illum(4), back(4);
    demodulate(color, albedo, illum);
    EXPECT_EQ(illum[0], vec3(1.f, 0.8f, 0.1f));
    EXPECT_EQ(illum[2], vec3(0.f));
    // Black or negative albedo: divided by the epsilon, not by zero.
    EXPECT_FLOAT_EQ(illum[3].r, 0.3f / kDefaultAlbedoEpsilon);
    EXPECT_FLOAT_EQ(illum[3].g, 0.3f / kDefaultAlbedoEpsilon);
    remodulate(illum, albedo, back);
    EXPECT_LE(maxRelDiff(back, color), 1e-6);
    // In place.
    std::vector<vec3> inPlace = color;
    demodulate(inPlace, albedo, inPlace);
    EXPECT_EQ(inPlace, illum);
    // A constant image through demodulate + remodulate stays constant.
    const std::vector<vec3> c = constantImage(16, 0.7f);
    std::vector<vec3> tex(16);
    for (int i = 0; i < 16; ++i) tex[i] = vec3(0.1f + 0.05f * i);
    std::vector<vec3> d(16), r(16);
    demodulate(c, tex, d);
    remodulate(d, tex, r);
    EXPECT_LE(maxRelDiff(r, c), 1e-6);
}

TEST(DenoiseModulation, FiniteForExtremeInputs) {
    const std::vector<vec3> color{vec3(3e38f), vec3(-3e38f), vec3(1e20f), vec3(1e-30f)};
    const std::vector<vec3> albedo{vec3(1e-30f), vec3(0.f), vec3(3e38f), vec3(3e38f)};
    std::vector<vec3> out(4), back(4);
    demodulate(color, albedo, out);
    EXPECT_TRUE(allFinite(out));
    remodulate(out, albedo, back);
    EXPECT_TRUE(allFinite(back));
    EXPECT_THROW(demodulate(color, albedo, out, 0.f), std::invalid_argument);
}
