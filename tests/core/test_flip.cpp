// FLIP and HDR-FLIP: known answers derived by hand from the papers' formulas,
// a direct (slow, double, full 2D kernels) evaluation of the paper's LDR-FLIP
// to check the separable implementation against, seeded property tests, and
// literal regression values.
#include <rtlab/core/flip.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/rng.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

using namespace rtlab;

namespace {

constexpr double kPiD = 3.14159265358979323846;
constexpr double kDefaultPpd = 0.7 * (3840.0 / 0.7) * kPiD / 180.0;

std::vector<vec3> uniformImage(int width, int height, vec3 colour) {
    return std::vector<vec3>(static_cast<std::size_t>(width) * height, colour);
}

float uniform01(std::uint32_t seed, std::uint32_t pixel, std::uint32_t dimension) {
    return sampleUniform(SampleKey{pixel, 0, 0, 0, seed}, dimension);
}

// A smooth colourful image plus seeded per-pixel texture, values in [0, 1].
std::vector<vec3> seededImage(int width, int height, std::uint32_t seed) {
    std::vector<vec3> image(static_cast<std::size_t>(width) * height);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const auto i = static_cast<std::uint32_t>(y * width + x);
            const float u = float(x) / float(width), v = float(y) / float(height);
            const vec3 base{0.5f + 0.3f * std::sin(6.f * u + float(seed)), 0.4f + 0.3f * v,
                            0.5f + 0.25f * std::cos(5.f * v + 2.f * u)};
            const vec3 texture{uniform01(seed, i, 0), uniform01(seed, i, 1), uniform01(seed, i, 2)};
            image[i] = glm::clamp(0.75f * base + 0.25f * texture, vec3(0.f), vec3(1.f));
        }
    return image;
}

// `image` plus amplitude * (seeded noise in [-1, 1]), clamped to [0, 1].
std::vector<vec3> withNoise(const std::vector<vec3>& image, float amplitude, std::uint32_t seed) {
    std::vector<vec3> noisy = image;
    for (std::size_t i = 0; i < noisy.size(); ++i)
        for (int c = 0; c < 3; ++c) {
            const float n = 2.f * uniform01(seed, static_cast<std::uint32_t>(i), 10u + c) - 1.f;
            noisy[i][c] = std::clamp(noisy[i][c] + amplitude * n, 0.f, 1.f);
        }
    return noisy;
}

std::vector<vec3> seededHdrImage(int width, int height, std::uint32_t seed) {
    std::vector<vec3> image = seededImage(width, height, seed);
    // Spread over about 8 stops, with a few bright highlights.
    for (std::size_t i = 0; i < image.size(); ++i) {
        const float stops = 8.f * uniform01(seed, std::uint32_t(i), 40) - 4.f;
        image[i] *= std::exp2(stops);
        if (i % 97 == 0) image[i] *= 50.f;
    }
    return image;
}

float at(const FlipResult& r, int x, int y) { return r.errorMap[static_cast<std::size_t>(y) * r.width + x]; }

// ---------------------------------------------------------------------------
// A direct transcription of the FLIP paper's LDR pipeline: double precision,
// full (2r+1)^2 kernels normalised as 2D kernels, border pixels clamped. It
// shares no code with core/src/flip.cpp.

struct Direct {
    static double srgbToLinear(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }

    static constexpr double M[3][3] = {{10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0},
                                       {2613072.0 / 12288897.0, 8788810.0 / 12288897.0, 887015.0 / 12288897.0},
                                       {1425312.0 / 73733382.0, 8788810.0 / 73733382.0, 70074185.0 / 73733382.0}};

    static std::array<double, 3> white() {
        return {M[0][0] + M[0][1] + M[0][2], M[1][0] + M[1][1] + M[1][2], M[2][0] + M[2][1] + M[2][2]};
    }
    static std::array<double, 3> xyz(const std::array<double, 3>& rgb) {
        std::array<double, 3> out{};
        for (int r = 0; r < 3; ++r) out[r] = M[r][0] * rgb[0] + M[r][1] * rgb[1] + M[r][2] * rgb[2];
        return out;
    }
    static std::array<double, 3> rgbFromXyz(const std::array<double, 3>& xyzValue) {
        const glm::dmat3 forward(M[0][0], M[1][0], M[2][0], M[0][1], M[1][1], M[2][1], M[0][2], M[1][2], M[2][2]);
        const glm::dvec3 rgb = glm::inverse(forward) * glm::dvec3(xyzValue[0], xyzValue[1], xyzValue[2]);
        return {rgb.x, rgb.y, rgb.z};
    }
    static std::array<double, 3> huntLab(const std::array<double, 3>& rgb) {
        const auto w = white();
        const auto v = xyz(rgb);
        const auto f = [](double t) {
            const double d = 6.0 / 29.0;
            return t > d * d * d ? std::cbrt(t) : t / (3 * d * d) + 4.0 / 29.0;
        };
        const double fx = f(v[0] / w[0]), fy = f(v[1] / w[1]), fz = f(v[2] / w[2]);
        const double L = 116 * fy - 16;
        return {L, 0.01 * L * 500 * (fx - fy), 0.01 * L * 200 * (fy - fz)};
    }
    static double hyab(const std::array<double, 3>& a, const std::array<double, 3>& b) {
        return std::abs(a[0] - b[0]) + std::hypot(a[1] - b[1], a[2] - b[2]);
    }

    // 2D correlation with clamped borders.
    static std::vector<double> filter(const std::vector<double>& img, int w, int h, const std::vector<double>& k,
                                      int r) {
        std::vector<double> out(img.size(), 0.0);
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                double s = 0;
                for (int j = -r; j <= r; ++j)
                    for (int i = -r; i <= r; ++i) {
                        const int xx = std::clamp(x + i, 0, w - 1), yy = std::clamp(y + j, 0, h - 1);
                        s += k[(j + r) * (2 * r + 1) + (i + r)] * img[yy * w + xx];
                    }
                out[y * w + x] = s;
            }
        return out;
    }

    struct Perceived {
        std::vector<std::array<double, 3>> lab;
        std::vector<double> edge, point;
    };

    static Perceived perceive(const std::vector<vec3>& srgb, int w, int h, double ppd) {
        const std::size_t n = srgb.size();
        const auto wt = white();
        std::array<std::vector<double>, 3> opp{std::vector<double>(n), std::vector<double>(n), std::vector<double>(n)};
        std::vector<double> lum(n);
        for (std::size_t i = 0; i < n; ++i) {
            const auto v = xyz({srgbToLinear(srgb[i].x), srgbToLinear(srgb[i].y), srgbToLinear(srgb[i].z)});
            const double x = v[0] / wt[0], y = v[1] / wt[1], z = v[2] / wt[2];
            opp[0][i] = 116 * y - 16;
            opp[1][i] = 500 * (x - y);
            opp[2][i] = 200 * (y - z);
            lum[i] = y;
        }
        // CSF kernels: a1 sqrt(pi/b1) exp(-pi^2 d^2/b1) + a2 sqrt(pi/b2) exp(-pi^2 d^2/b2), d in degrees.
        const double params[3][4] = {{1, 0.0047, 0, 1e-5}, {1, 0.0053, 0, 1e-5}, {34.1, 0.04, 13.5, 0.025}};
        const int r = int(std::ceil(3 * std::sqrt(0.04 / (2 * kPiD * kPiD)) * ppd));
        std::array<std::vector<double>, 3> filtered;
        for (int c = 0; c < 3; ++c) {
            std::vector<double> k;
            double total = 0;
            for (int j = -r; j <= r; ++j)
                for (int i = -r; i <= r; ++i) {
                    const double d2 = (i * i + j * j) / (ppd * ppd);
                    const auto& p = params[c];
                    const double g = p[0] * std::sqrt(kPiD / p[1]) * std::exp(-kPiD * kPiD * d2 / p[1]) +
                                     p[2] * std::sqrt(kPiD / p[3]) * std::exp(-kPiD * kPiD * d2 / p[3]);
                    k.push_back(g);
                    total += g;
                }
            for (double& g : k) g /= total;
            filtered[c] = filter(opp[c], w, h, k, r);
        }
        Perceived out;
        for (std::size_t i = 0; i < n; ++i) {
            const double y = (filtered[0][i] + 16) / 116;
            const double x = y + filtered[1][i] / 500, z = y - filtered[2][i] / 200;
            auto rgb = rgbFromXyz({x * wt[0], y * wt[1], z * wt[2]});
            for (double& c : rgb) c = std::clamp(c, 0.0, 1.0);
            out.lab.push_back(huntLab(rgb));
        }
        // Features: Gaussian sd 0.5 * 0.082 * ppd, radius ceil(3 sd); 2D kernels normalised +1 / -1.
        const double sd = 0.5 * 0.082 * ppd;
        const int fr = int(std::ceil(3 * sd));
        const auto featureKernel = [&](bool edge, bool transpose) {
            std::vector<double> k;
            for (int j = -fr; j <= fr; ++j)
                for (int i = -fr; i <= fr; ++i) {
                    const double x = transpose ? j : i;
                    const double g = std::exp(-(i * i + j * j) / (2 * sd * sd));
                    k.push_back(edge ? -x * g : (x * x / (sd * sd) - 1) * g);
                }
            double pos = 0, neg = 0;
            for (double v : k) (v > 0 ? pos : neg) += v;
            for (double& v : k) v = v > 0 ? v / pos : (v < 0 ? v / -neg : 0);
            return k;
        };
        const auto ex = filter(lum, w, h, featureKernel(true, false), fr);
        const auto ey = filter(lum, w, h, featureKernel(true, true), fr);
        const auto px = filter(lum, w, h, featureKernel(false, false), fr);
        const auto py = filter(lum, w, h, featureKernel(false, true), fr);
        for (std::size_t i = 0; i < n; ++i) {
            out.edge.push_back(std::hypot(ex[i], ey[i]));
            out.point.push_back(std::hypot(px[i], py[i]));
        }
        return out;
    }

    static std::vector<double> ldrFlip(const std::vector<vec3>& test, const std::vector<vec3>& ref, int w, int h,
                                       double ppd) {
        const Perceived t = perceive(test, w, h, ppd), r = perceive(ref, w, h, ppd);
        const double cmax = std::pow(hyab(huntLab({0, 1, 0}), huntLab({0, 0, 1})), 0.7);
        std::vector<double> errors;
        for (std::size_t i = 0; i < test.size(); ++i) {
            const double p = std::pow(hyab(t.lab[i], r.lab[i]), 0.7);
            const double dEc =
                p < 0.4 * cmax ? 0.95 / (0.4 * cmax) * p : 0.95 + (p - 0.4 * cmax) / (cmax - 0.4 * cmax) * 0.05;
            const double dEf = std::pow(
                std::max(std::abs(t.edge[i] - r.edge[i]), std::abs(t.point[i] - r.point[i])) / std::sqrt(2.0), 0.5);
            errors.push_back(std::pow(dEc, 1 - dEf));
        }
        return errors;
    }
};

}  // namespace

// ---------------------------------------------------------------------------
// LDR-FLIP: known answers

TEST(FlipLdr, IdenticalImagesGiveZeroEverywhere) {
    for (std::uint32_t seed : {1u, 2u, 3u}) {
        const std::vector<vec3> image = seededImage(37, 23, seed);
        const FlipResult r = ldrFlip(image, image, 37, 23);
        ASSERT_EQ(r.errorMap.size(), image.size());
        EXPECT_EQ(r.width, 37);
        EXPECT_EQ(r.height, 23);
        for (float e : r.errorMap) ASSERT_EQ(e, 0.f) << "seed " << seed;
        EXPECT_EQ(r.mean, 0.0);
        EXPECT_EQ(r.median, 0.0);
        EXPECT_EQ(r.maxError, 0.0);
        EXPECT_EQ(r.exposureCount, 0);
    }
}

// Uniform images: every filter sees a constant (borders clamp), so the CSF
// blur returns the colour and the edge/point detectors return 0: deltaEf = 0
// and FLIP = deltaEc, the colour formula evaluated on the two colours.
//
// Derivation (FLIP paper, colour pipeline), with cmax first:
//   green (0,1,0): XYZ/white = (0.37624, 0.71517, 0.10946) -> L*a*b* =
//     (87.736, -86.179, 83.183) -> Hunt (a, b scaled by L/100) = (87.736, -75.610, 72.981)
//   blue (0,0,1): L*a*b* = (32.298, 79.194, -107.859) -> Hunt (32.298, 25.578, -34.836)
//   HyAB = |87.736 - 32.298| + sqrt(101.188^2 + 107.817^2) = 55.438 + 147.864 = 203.302
//   cmax = 203.302^0.7 = 41.2761, pc * cmax = 16.5104
// White (1,1,1) vs black: L*a*b* (100, 0, 0) vs (0, 0, 0), HyAB = 100, 100^0.7 = 25.1189 > 16.5104,
//   so deltaEc = 0.95 + (25.1189 - 16.5104) / (41.2761 - 16.5104) * 0.05 = 0.967380.
// sRGB grey 0.5 vs 0.25: linear 0.214041 vs 0.050876, L* = 116 cbrt(Y) - 16 = 53.389 vs 26.978,
//   HyAB = 26.411, 26.411^0.7 = 9.8899 < 16.5104, so deltaEc = 0.95 / 16.5104 * 9.8899 = 0.569059.
// Green vs blue: HyAB^0.7 = cmax exactly, so deltaEc = 1 (the largest FLIP error).
TEST(FlipLdr, UniformColourPairsMatchTheHandDerivedFormula) {
    struct Case {
        vec3 test, reference;
        double expected;
    };
    const Case cases[] = {
        {vec3(0.f), vec3(1.f), 0.967380},
        {vec3(1.f), vec3(0.f), 0.967380},
        {vec3(0.25f), vec3(0.5f), 0.569059},
        {vec3(0.f, 0.f, 1.f), vec3(0.f, 1.f, 0.f), 1.0},
    };
    for (const Case& c : cases) {
        const int w = 40, h = 30;
        const FlipResult r = ldrFlip(uniformImage(w, h, c.test), uniformImage(w, h, c.reference), w, h);
        // Centre, corner and the statistics all equal the formula.
        EXPECT_NEAR(at(r, w / 2, h / 2), c.expected, 2e-5);
        EXPECT_NEAR(at(r, 0, 0), c.expected, 2e-5);
        EXPECT_NEAR(r.mean, c.expected, 2e-5);
        EXPECT_NEAR(r.median, c.expected, 2e-5);
        EXPECT_LE(r.maxError, 1.0);
    }
}

TEST(FlipLdr, MatchesDirectEvaluationOfThePaperFormulas) {
    // Small seeded images, textured, plus a sharp square, so that CSF
    // blurring, borders and both feature detectors all matter.
    for (std::uint32_t seed : {7u, 8u}) {
        const int w = 26, h = 19;
        const std::vector<vec3> reference = seededImage(w, h, seed);
        std::vector<vec3> test = withNoise(reference, 0.15f, seed + 100);
        for (int y = 5; y < 9; ++y)
            for (int x = 3; x < 8; ++x) test[y * w + x] = vec3(0.95f, 0.9f, 0.1f);
        for (double ppd : {kDefaultPpd, 20.0}) {
            const FlipResult fast = ldrFlip(test, reference, w, h, FlipOptions{ppd});
            const std::vector<double> direct = Direct::ldrFlip(test, reference, w, h, ppd);
            double worst = 0;
            for (std::size_t i = 0; i < direct.size(); ++i)
                worst = std::max(worst, std::abs(double(fast.errorMap[i]) - direct[i]));
            EXPECT_LT(worst, 2e-5) << "seed " << seed << " ppd " << ppd;
        }
    }
}

TEST(FlipLdr, PointAndEdgeDifferencesRaiseErrorLocally) {
    const int w = 48, h = 40;
    const vec3 grey(0.5f);
    const std::vector<vec3> reference = uniformImage(w, h, grey);

    // A one-pixel dot: error at the dot, exactly 0 beyond the filters' reach
    // (CSF radius 10, feature radius 9 at the default 67 ppd).
    std::vector<float> peakByContrast;
    for (float dot : {0.55f, 0.7f, 0.9f}) {
        std::vector<vec3> test = reference;
        test[20 * w + 24] = vec3(dot);
        const FlipResult r = ldrFlip(test, reference, w, h);
        EXPECT_GT(at(r, 24, 20), 0.f);
        EXPECT_EQ(at(r, 2, 2), 0.f);
        EXPECT_EQ(at(r, 24 + 11, 20), 0.f);
        EXPECT_GE(at(r, 24, 20), at(r, 24 + 3, 20));
        peakByContrast.push_back(at(r, 24, 20));
    }
    EXPECT_LT(peakByContrast[0], peakByContrast[1]);
    EXPECT_LT(peakByContrast[1], peakByContrast[2]);

    // A vertical edge moved by one pixel: error along the edge, none far away.
    std::vector<vec3> edgeReference = reference, edgeTest = reference;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            if (x >= 24) edgeReference[y * w + x] = vec3(0.9f);
            if (x >= 25) edgeTest[y * w + x] = vec3(0.9f);
        }
    const FlipResult edge = ldrFlip(edgeTest, edgeReference, w, h);
    EXPECT_GT(at(edge, 24, 20), 0.1f);
    EXPECT_EQ(at(edge, 2, 20), 0.f);
    EXPECT_EQ(at(edge, 45, 20), 0.f);
    // The edge runs the full height, so every row sees the same error.
    EXPECT_EQ(at(edge, 24, 0), at(edge, 24, 20));

    // The feature term only ever raises the error: deltaE = deltaEc^(1 - deltaEf)
    // >= deltaEc. A vertical one-pixel grey line (sRGB 0.6 on 0.5) is blurred
    // by the achromatic CSF along x only (it is constant along y), so at the
    // line its luminance is base + g0 (line - base), g0 the centre weight of
    // the normalised 1D Gaussian exp(-pi^2 (k / ppd)^2 / 0.0047), k = -10..10:
    // g0 = 1 / 2.592278 = 0.385760. Linear 0.214041 and 0.318547 give y' =
    // 0.254355, L* 57.497 against 53.389, HyAB 4.108, ^0.7 = 2.6889 < pc cmax,
    // so deltaEc = 0.95 / 16.5104 * 2.6889 = 0.154715. The point detector sees
    // the line, so the error there is clearly above that.
    double centreWeightSum = 0.0;
    for (int k = -10; k <= 10; ++k) {
        const double degrees = k / kDefaultPpd;
        centreWeightSum += std::exp(-kPiD * kPiD * degrees * degrees / 0.0047);
    }
    EXPECT_NEAR(1.0 / centreWeightSum, 0.385760, 1e-6);
    const double colourOnlyError = 0.154715;
    std::vector<vec3> line = reference;
    for (int y = 0; y < h; ++y) line[y * w + 24] = vec3(0.6f);
    const FlipResult lineResult = ldrFlip(line, reference, w, h);
    EXPECT_GT(at(lineResult, 24, 20), colourOnlyError + 0.02);
    // Where the CSF still reaches but the features no longer differ much, the
    // error is far smaller.
    EXPECT_LT(at(lineResult, 24 + 6, 20), 0.5 * at(lineResult, 24, 20));
}

TEST(FlipLdr, IsSymmetricInTestAndReference) {
    // HyAB and |feature difference| are symmetric, so LDR-FLIP is exactly.
    const std::vector<vec3> a = seededImage(31, 17, 4);
    const std::vector<vec3> b = withNoise(a, 0.1f, 5);
    const FlipResult ab = ldrFlip(a, b, 31, 17);
    const FlipResult ba = ldrFlip(b, a, 31, 17);
    EXPECT_EQ(ab.errorMap, ba.errorMap);
    EXPECT_GT(ab.mean, 0.0);
}

// ---------------------------------------------------------------------------
// LDR-FLIP: properties (seeded)

TEST(FlipLdr, ErrorsStayInTheUnitIntervalForRandomPairs) {
    for (std::uint32_t seed = 0; seed < 6; ++seed) {
        const int w = 21 + int(seed), h = 13 + 2 * int(seed);
        // Independent noise images: the worst case for both pipelines.
        std::vector<vec3> a(static_cast<std::size_t>(w) * h), b(a.size());
        for (std::size_t i = 0; i < a.size(); ++i)
            for (int c = 0; c < 3; ++c) {
                a[i][c] = uniform01(seed, std::uint32_t(i), c) > 0.5f ? 1.f : 0.f;
                b[i][c] = uniform01(seed + 50, std::uint32_t(i), c);
            }
        const FlipResult r = ldrFlip(a, b, w, h);
        for (float e : r.errorMap) {
            ASSERT_TRUE(std::isfinite(e));
            ASSERT_GE(e, 0.f);
            ASSERT_LE(e, 1.f);
        }
        EXPECT_GT(r.mean, 0.1);
        EXPECT_LE(r.median, r.maxError);
    }
}

TEST(FlipLdr, MoreNoiseGivesAHigherMeanError) {
    for (std::uint32_t seed : {11u, 12u, 13u}) {
        const std::vector<vec3> reference = seededImage(64, 48, seed);
        double previous = 0.0;
        for (float amplitude : {0.01f, 0.03f, 0.1f, 0.3f}) {
            const FlipResult r = ldrFlip(withNoise(reference, amplitude, seed), reference, 64, 48);
            EXPECT_GT(r.mean, previous) << "seed " << seed << " amplitude " << amplitude;
            previous = r.mean;
        }
    }
}

TEST(FlipLdr, IsIndependentOfTheThreadCount) {
    const std::vector<vec3> reference = seededImage(83, 61, 21);
    const std::vector<vec3> test = withNoise(reference, 0.2f, 22);
    FlipResult single, many;
    {
        ThreadLimit limit(1);
        single = ldrFlip(test, reference, 83, 61);
    }
    many = ldrFlip(test, reference, 83, 61);
    EXPECT_EQ(single.errorMap, many.errorMap);
    EXPECT_EQ(single.mean, many.mean);
    const FlipResult again = ldrFlip(test, reference, 83, 61);
    EXPECT_EQ(again.errorMap, many.errorMap);
}

// Literal regression values of this implementation (not from the papers):
// they pin the numbers down against accidental changes.
TEST(FlipLdr, LiteralRegressionValues) {
    const std::vector<vec3> reference = seededImage(32, 24, 99);
    const FlipResult r = ldrFlip(withNoise(reference, 0.1f, 98), reference, 32, 24);
    EXPECT_NEAR(r.mean, 0.130701513, 1e-6);
    EXPECT_NEAR(r.median, 0.123278230, 1e-6);
    EXPECT_NEAR(at(r, 10, 7), 0.0582038872, 1e-6);
}

// ---------------------------------------------------------------------------
// Sizes, sanitising, errors

TEST(FlipLdr, TinyImagesWork) {
    const vec3 red(1.f, 0.f, 0.f), blue(0.f, 0.f, 1.f);
    const FlipResult one = ldrFlip({red}, {blue}, 1, 1);
    ASSERT_EQ(one.errorMap.size(), 1u);
    EXPECT_GT(one.errorMap[0], 0.5f);
    EXPECT_LE(one.errorMap[0], 1.f);
    EXPECT_EQ(ldrFlip({red}, {red}, 1, 1).errorMap[0], 0.f);

    const std::vector<vec3> a = seededImage(3, 2, 5), b = seededImage(3, 2, 6);
    const FlipResult small = ldrFlip(a, b, 3, 2);
    ASSERT_EQ(small.errorMap.size(), 6u);
    for (float e : small.errorMap) {
        EXPECT_TRUE(std::isfinite(e));
        EXPECT_GE(e, 0.f);
        EXPECT_LE(e, 1.f);
    }
    EXPECT_GT(small.mean, 0.0);
    EXPECT_EQ(ldrFlip(a, a, 3, 2).mean, 0.0);
    // A single row and a single column (kernels much wider than the image).
    EXPECT_GT(ldrFlip(seededImage(9, 1, 1), seededImage(9, 1, 2), 9, 1).mean, 0.0);
    EXPECT_GT(ldrFlip(seededImage(1, 9, 1), seededImage(1, 9, 2), 1, 9).mean, 0.0);
}

TEST(FlipLdr, NonFiniteAndOutOfRangeInputIsSanitised) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    const std::vector<vec3> reference = seededImage(12, 10, 3);
    std::vector<vec3> dirty = reference, clean = reference;
    dirty[5] = vec3(nan, 0.5f, nan);
    clean[5] = vec3(0.f, 0.5f, 0.f);
    dirty[17] = vec3(inf, -inf, 2.f);
    clean[17] = vec3(1.f, 0.f, 1.f);
    dirty[30] = vec3(-0.5f, 1.5f, 0.25f);
    clean[30] = vec3(0.f, 1.f, 0.25f);
    const FlipResult d = ldrFlip(dirty, reference, 12, 10);
    for (float e : d.errorMap) ASSERT_TRUE(std::isfinite(e));
    EXPECT_TRUE(std::isfinite(d.mean));
    // NaN -> 0 and clamping to [0, 1] are exactly what happens.
    EXPECT_EQ(d.errorMap, ldrFlip(clean, reference, 12, 10).errorMap);
    // A NaN reference too.
    const FlipResult both = ldrFlip(dirty, dirty, 12, 10);
    EXPECT_EQ(both.mean, 0.0);
}

TEST(FlipLdr, BadSizesAndOptionsThrow) {
    const std::vector<vec3> six = seededImage(3, 2, 1);
    EXPECT_THROW(ldrFlip(six, six, 2, 2), std::invalid_argument);
    EXPECT_THROW(ldrFlip(six, std::vector<vec3>(5), 3, 2), std::invalid_argument);
    EXPECT_THROW(ldrFlip({}, {}, 0, 0), std::invalid_argument);
    EXPECT_THROW(ldrFlip({}, {}, 0, 5), std::invalid_argument);
    EXPECT_THROW(ldrFlip(six, six, -3, -2), std::invalid_argument);
    EXPECT_THROW(ldrFlip(six, six, 3, 2, FlipOptions{0.0}), std::invalid_argument);
    EXPECT_THROW(ldrFlip(six, six, 3, 2, FlipOptions{std::nan("")}), std::invalid_argument);
    EXPECT_THROW(ldrFlip(six, six, 3, 2, FlipOptions{-67.0}), std::invalid_argument);
    EXPECT_THROW(hdrFlip(six, six, 3, 2, FlipOptions{std::numeric_limits<double>::infinity()}), std::invalid_argument);
    EXPECT_THROW(hdrFlip(six, six, 3, 2, FlipOptions{1e12}), std::invalid_argument);
    EXPECT_THROW(hdrFlip(six, std::vector<vec3>(7), 3, 2), std::invalid_argument);
    EXPECT_THROW(hdrFlip({}, {}, 0, 0), std::invalid_argument);
    try {
        ldrFlip(six, std::vector<vec3>(5), 3, 2);
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("3x2"), std::string::npos) << e.what();
    }
}

// ---------------------------------------------------------------------------
// HDR-FLIP

TEST(FlipHdr, IdenticalImagesGiveZero) {
    const std::vector<vec3> image = seededHdrImage(40, 30, 5);
    const FlipResult r = hdrFlip(image, image, 40, 30);
    for (float e : r.errorMap) ASSERT_EQ(e, 0.f);
    EXPECT_EQ(r.mean, 0.0);
    EXPECT_GE(r.exposureCount, 2);
    EXPECT_LT(r.startExposure, r.stopExposure);
}

// Uniform grey reference of luminance L and test 2L: Ymax = Ymedian = L, so the
// start and stop exposures are both log2(x85 / L), with x85 the input where
// ACES gives 0.85: (0.9036 - 0.85 * 0.8748) x^2 + (0.018 - 0.85 * 0.354) x
// - 0.85 * 0.14 = 0 -> x85 = 2.1188723. Two exposures, both the same: the
// reference maps to grey 0.85 and the test to t(2 x85) = 0.9396736 (linear).
// LDR-FLIP of the uniform pair is deltaEc: L* = 116 cbrt(Y) - 16 = 93.883 vs
// 97.619, HyAB = 3.7357, ^0.7 = 2.5157 < pc cmax, so 0.95 / 16.5104 * 2.5157 = 0.144753.
TEST(FlipHdr, UniformGreyPairMatchesTheHandDerivedExposureAndFormula) {
    const double x85 = 2.1188723239873157;
    for (float luminance : {0.01f, 1.f, 300.f}) {
        const int w = 36, h = 28;
        const FlipResult r =
            hdrFlip(uniformImage(w, h, vec3(2.f * luminance)), uniformImage(w, h, vec3(luminance)), w, h);
        EXPECT_EQ(r.exposureCount, 2);
        EXPECT_NEAR(r.startExposure, std::log2(x85 / luminance), 1e-5);
        EXPECT_NEAR(r.stopExposure, std::log2(x85 / luminance), 1e-5);
        EXPECT_NEAR(at(r, w / 2, h / 2), 0.144753, 5e-5);
        EXPECT_NEAR(r.mean, 0.144753, 5e-5);
    }
}

TEST(FlipHdr, ScaledImageGivesAPositiveErrorGrowingWithTheScale) {
    const std::vector<vec3> reference = seededHdrImage(48, 36, 9);
    double previous = 0.0;
    for (float scale : {1.05f, 1.3f, 2.f, 4.f}) {
        std::vector<vec3> test = reference;
        for (vec3& c : test) c *= scale;
        const FlipResult r = hdrFlip(test, reference, 48, 36);
        EXPECT_GT(r.mean, previous) << "scale " << scale;
        for (float e : r.errorMap) {
            ASSERT_GE(e, 0.f);
            ASSERT_LE(e, 1.f);
        }
        previous = r.mean;
    }
}

TEST(FlipHdr, ExposureRangeFollowsTheReference) {
    // Max luminance 8 and median 0.6 (grey pixels, luminance = value):
    // start log2(x85 / 8), stop log2(x85 / 0.6), 3.74 stops apart -> 4 exposures.
    const double x85 = 2.1188723239873157;
    std::vector<vec3> reference = uniformImage(5, 1, vec3(0.6f));
    reference[0] = vec3(8.f);
    reference[1] = vec3(0.1f);
    const FlipResult r = hdrFlip(reference, reference, 5, 1);
    EXPECT_NEAR(r.startExposure, std::log2(x85 / 8.0), 1e-5);
    EXPECT_NEAR(r.stopExposure, std::log2(x85 / 0.6), 1e-5);
    EXPECT_EQ(r.exposureCount, 4);

    // Mostly black reference: the median of the positive luminances (here
    // 2, of {1, 2, 4}) replaces the zero median.
    std::vector<vec3> mostlyBlack = uniformImage(7, 1, vec3(0.f));
    mostlyBlack[0] = vec3(1.f);
    mostlyBlack[3] = vec3(2.f);
    mostlyBlack[6] = vec3(4.f);
    const FlipResult dark = hdrFlip(mostlyBlack, mostlyBlack, 7, 1);
    EXPECT_NEAR(dark.startExposure, std::log2(x85 / 4.0), 1e-5);
    EXPECT_NEAR(dark.stopExposure, std::log2(x85 / 2.0), 1e-5);

    // Black reference: exposure 0, and a visible test still shows an error.
    const FlipResult black = hdrFlip(uniformImage(6, 4, vec3(0.5f)), uniformImage(6, 4, vec3(0.f)), 6, 4);
    EXPECT_EQ(black.startExposure, 0.0);
    EXPECT_EQ(black.stopExposure, 0.0);
    EXPECT_EQ(black.exposureCount, 2);
    EXPECT_GT(black.mean, 0.1);
}

TEST(FlipHdr, TinyImagesAndNonFiniteInputStayFinite) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    const FlipResult one = hdrFlip({vec3(2.f, 1.f, 0.5f)}, {vec3(1.f)}, 1, 1);
    ASSERT_EQ(one.errorMap.size(), 1u);
    EXPECT_GT(one.errorMap[0], 0.f);
    EXPECT_LE(one.errorMap[0], 1.f);

    const std::vector<vec3> reference = seededHdrImage(3, 2, 2);
    std::vector<vec3> dirty = reference, clean = reference;
    dirty[0] = vec3(nan, inf, -1.f);
    clean[0] = vec3(0.f, 65536.f, 0.f);
    dirty[4] = vec3(-inf, 1e30f, nan);
    clean[4] = vec3(0.f, 65536.f, 0.f);
    const FlipResult d = hdrFlip(dirty, reference, 3, 2);
    for (float e : d.errorMap) ASSERT_TRUE(std::isfinite(e));
    EXPECT_EQ(d.errorMap, hdrFlip(clean, reference, 3, 2).errorMap);
    // Non-finite values in the reference (which sets the exposures) too.
    const FlipResult r = hdrFlip(reference, dirty, 3, 2);
    for (float e : r.errorMap) ASSERT_TRUE(std::isfinite(e));
    EXPECT_TRUE(std::isfinite(r.startExposure));
    EXPECT_TRUE(std::isfinite(r.stopExposure));
}

TEST(FlipHdr, IsRoughlySymmetricAndThreadCountIndependent) {
    // The exposures come from the reference, so swapping is not exact, but a
    // difference is a difference either way round.
    const std::vector<vec3> a = seededHdrImage(40, 32, 31);
    std::vector<vec3> b = a;
    for (std::size_t i = 0; i < b.size(); i += 3) b[i] *= 1.5f;
    const FlipResult ab = hdrFlip(a, b, 40, 32);
    const FlipResult ba = hdrFlip(b, a, 40, 32);
    EXPECT_GT(ab.mean, 0.0);
    EXPECT_GT(ba.mean, 0.0);
    EXPECT_LT(std::max(ab.mean, ba.mean) / std::min(ab.mean, ba.mean), 1.5);
    FlipResult single;
    {
        ThreadLimit limit(1);
        single = hdrFlip(a, b, 40, 32);
    }
    EXPECT_EQ(single.errorMap, ab.errorMap);
}

TEST(FlipHdr, LiteralRegressionValues) {
    const std::vector<vec3> reference = seededHdrImage(32, 24, 77);
    std::vector<vec3> test = reference;
    for (std::size_t i = 0; i < test.size(); ++i) test[i] *= 0.8f + 0.4f * uniform01(76, std::uint32_t(i), 0);
    const FlipResult r = hdrFlip(test, reference, 32, 24);
    EXPECT_EQ(r.exposureCount, 9);
    EXPECT_NEAR(r.startExposure, -6.79251568, 1e-5);
    EXPECT_NEAR(r.stopExposure, 2.04076741, 1e-5);
    EXPECT_NEAR(r.mean, 0.0723976288, 1e-6);
    EXPECT_NEAR(at(r, 10, 7), 0.0737054944, 1e-6);
}

// ---------------------------------------------------------------------------
// Error image

TEST(FlipErrorImage, MapsErrorsThroughMagma) {
    FlipResult r;
    r.width = 4;
    r.height = 1;
    r.errorMap = {0.f, 1.f, 0.5f, std::numeric_limits<float>::quiet_NaN()};
    const Image image = flipErrorImage(r);
    ASSERT_EQ(image.width(), 4);
    ASSERT_EQ(image.height(), 1);
    const std::vector<vec3> rgb = image.rgbLayer("");
    // magma[0] = (0.001462, 0.000466, 0.013866), magma[255] = (0.987053, 0.991438, 0.749504)
    // (display values; the image holds them sRGB-decoded).
    EXPECT_NEAR(rgb[0].z, srgbToLinear(0.013866f), 1e-7);
    EXPECT_NEAR(rgb[1].x, srgbToLinear(0.987053f), 1e-7);
    EXPECT_NEAR(rgb[1].y, srgbToLinear(0.991438f), 1e-7);
    EXPECT_NEAR(rgb[1].z, srgbToLinear(0.749504f), 1e-7);
    // NaN is shown as 0; magma's brightness rises with the error.
    EXPECT_EQ(rgb[3], rgb[0]);
    const auto luminance = [](vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; };
    EXPECT_LT(luminance(rgb[0]), luminance(rgb[2]));
    EXPECT_LT(luminance(rgb[2]), luminance(rgb[1]));

    FlipResult broken = r;
    broken.errorMap.pop_back();
    EXPECT_THROW(flipErrorImage(broken), std::invalid_argument);
}

TEST(FlipErrorImage, OfARealResult) {
    const std::vector<vec3> reference = seededImage(20, 10, 1);
    const FlipResult r = ldrFlip(withNoise(reference, 0.2f, 2), reference, 20, 10);
    const Image image = flipErrorImage(r);
    EXPECT_EQ(image.width(), 20);
    EXPECT_EQ(image.height(), 10);
    EXPECT_TRUE(image.hasChannel("R") && image.hasChannel("G") && image.hasChannel("B"));
}
