// Log-log plots: axis ranges, data -> pixel mapping, skipped points, text,
// legend placement, PNG output and determinism.
#include <rtlab/core/plot.hpp>

#include <stb_image.h>  // STB_IMAGE_IMPLEMENTATION lives in test_image.cpp

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace rtlab;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// A fresh, empty directory per test, removed afterwards.
class PlotFiles : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir = fs::temp_directory_path() / ("rtlab_test_plot_" + std::to_string(::getpid()) + "_" + info->name());
        fs::remove_all(dir);
        fs::create_directories(dir);
    }
    void TearDown() override { fs::remove_all(dir); }

    fs::path dir;
};

std::vector<unsigned char> readBytes(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Decoded 8-bit RGB PNG.
struct DecodedPng {
    int width = 0;
    int height = 0;
    std::vector<unsigned char> rgb;
};

DecodedPng decodePng(const fs::path& path) {
    DecodedPng png;
    int channelsInFile = 0;
    unsigned char* data = stbi_load(path.c_str(), &png.width, &png.height, &channelsInFile, 3);
    if (data == nullptr) return png;
    png.rgb.assign(data, data + static_cast<std::size_t>(png.width) * png.height * 3);
    stbi_image_free(data);
    return png;
}

// The 8-bit sRGB code writePng produces for a linear value.
int srgbCode(float linear) {
    const double v = std::clamp(static_cast<double>(linear), 0.0, 1.0);
    const double encoded = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
    return static_cast<int>(std::lround(encoded * 255.0));
}

vec3 pixelAt(const Image& image, int x, int y) {
    const std::size_t i = static_cast<std::size_t>(y) * image.width() + x;
    return {image.channel("R")[i], image.channel("G")[i], image.channel("B")[i]};
}

bool isBackground(const Image& image, int x, int y) { return pixelAt(image, x, y) == vec3(1.f); }

// The pixel containing the mapped position of a data point.
glm::ivec2 pixelOf(const PlotFrame& frame, double x, double y) {
    const glm::dvec2 p = frame.toPixel(x, y);
    return {static_cast<int>(std::floor(p.x)), static_cast<int>(std::floor(p.y))};
}

PlotOptions smallOptions() {
    PlotOptions options;
    options.width = 480;
    options.height = 320;
    return options;
}

}  // namespace

// ---------------------------------------------------------------------------
// Axes

TEST(PlotAxes, DecadeLabelsUsePlainNumbersOnlyFromHundredthsToTenThousand) {
    EXPECT_EQ(decadeLabel(-5), "1e-5");
    EXPECT_EQ(decadeLabel(-3), "1e-3");
    EXPECT_EQ(decadeLabel(-2), "0.01");
    EXPECT_EQ(decadeLabel(-1), "0.1");
    EXPECT_EQ(decadeLabel(0), "1");
    EXPECT_EQ(decadeLabel(1), "10");
    EXPECT_EQ(decadeLabel(2), "100");
    EXPECT_EQ(decadeLabel(4), "10000");
    EXPECT_EQ(decadeLabel(5), "1e5");
}

TEST(PlotAxes, LogPlottableMeansFiniteAndPositive) {
    EXPECT_TRUE(isLogPlottable(1e-300));
    EXPECT_TRUE(isLogPlottable(5.0));
    EXPECT_FALSE(isLogPlottable(0.0));
    EXPECT_FALSE(isLogPlottable(-1.0));
    EXPECT_FALSE(isLogPlottable(kNaN));
    EXPECT_FALSE(isLogPlottable(kInf));
}

TEST(PlotAxes, RangesAreWholeDecadesEnclosingDrawablePoints) {
    // Undrawable points (y = 0, x = NaN) do not widen the range.
    const std::vector<PlotSeries> series = {
        {"a", {15.0, 3000.0, 1e9, kNaN}, {0.5, 2e-4, 0.0, 1e-20}},
        {"b", {1000.0}, {0.01}},
    };
    const PlotFrame frame = computePlotFrame(series, PlotOptions{});
    EXPECT_EQ(frame.xDecadeMin, 1);
    EXPECT_EQ(frame.xDecadeMax, 4);
    EXPECT_EQ(frame.yDecadeMin, -4);
    EXPECT_EQ(frame.yDecadeMax, 0);
}

TEST(PlotAxes, ExactPowersOfTenAreRangeBounds) {
    const PlotFrame frame = computePlotFrame({{"a", {10.0, 1000.0}, {1e-3, 1.0}}}, PlotOptions{});
    EXPECT_EQ(frame.xDecadeMin, 1);
    EXPECT_EQ(frame.xDecadeMax, 3);
    EXPECT_EQ(frame.yDecadeMin, -3);
    EXPECT_EQ(frame.yDecadeMax, 0);
}

TEST(PlotAxes, EqualValuesAreWidenedByOneDecadeEachSide) {
    const PlotFrame frame = computePlotFrame({{"a", {100.0, 100.0}, {0.05, 0.05}}}, PlotOptions{});
    EXPECT_EQ(frame.xDecadeMin, 1);
    EXPECT_EQ(frame.xDecadeMax, 3);
    EXPECT_EQ(frame.yDecadeMin, -3);
    EXPECT_EQ(frame.yDecadeMax, 0);
}

TEST(PlotAxes, ToPixelMapsRangeBoundsToDataAreaCornerPixels) {
    const PlotFrame frame = computePlotFrame({{"a", {10.0, 1e4}, {1e-4, 1.0}}}, PlotOptions{});
    const PixelRect& area = frame.plotArea;
    ASSERT_FALSE(area.empty());
    EXPECT_GT(area.left, 0);
    EXPECT_LT(area.right, 959);
    EXPECT_GT(area.top, 0);
    EXPECT_LT(area.bottom, 639);
    EXPECT_EQ(pixelOf(frame, 10.0, 1e-4), glm::ivec2(area.left, area.bottom));
    EXPECT_EQ(pixelOf(frame, 1e4, 1.0), glm::ivec2(area.right, area.top));
    // Log spacing: each decade takes the same number of pixels.
    const glm::dvec2 a = frame.toPixel(10.0, 1e-4);
    const glm::dvec2 b = frame.toPixel(100.0, 1e-3);
    const glm::dvec2 c = frame.toPixel(1000.0, 1e-2);
    EXPECT_NEAR(b.x - a.x, c.x - b.x, 1e-9);
    EXPECT_NEAR(b.y - a.y, c.y - b.y, 1e-9);
    EXPECT_LT(b.y, a.y);  // larger y is higher up
}

// ---------------------------------------------------------------------------
// Rendering

TEST(PlotRender, MarkerPixelHasTheSeriesColour) {
    const std::vector<PlotSeries> series = {{"raw", {10.0, 300.0, 1000.0}, {1.0, 0.02, 0.001}}};
    PlotReport report;
    const Image image = renderLogLogPlot(series, PlotOptions{}, &report);
    ASSERT_EQ(image.width(), 960);
    ASSERT_EQ(image.height(), 640);
    const glm::ivec2 p = pixelOf(computePlotFrame(series, PlotOptions{}), 300.0, 0.02);
    ASSERT_FALSE(report.legendArea.contains(p.x, p.y));
    EXPECT_EQ(pixelAt(image, p.x, p.y), plotSeriesColour(0));
    EXPECT_EQ(report.pointsDrawn, 3u);
    EXPECT_EQ(report.pointsSkipped, 0u);
}

TEST(PlotRender, EachSeriesIsDrawnInItsPaletteColour) {
    const std::vector<PlotSeries> series = {
        {"raw", {20.0}, {0.5}}, {"svgf", {200.0}, {0.05}}, {"svgf after 8 frames", {2000.0}, {0.005}}};
    PlotReport report;
    const Image image = renderLogLogPlot(series, smallOptions(), &report);
    const PlotFrame frame = computePlotFrame(series, smallOptions());
    for (std::size_t s = 0; s < series.size(); ++s) {
        const glm::ivec2 p = pixelOf(frame, series[s].x[0], series[s].y[0]);
        if (report.legendArea.contains(p.x, p.y)) continue;
        EXPECT_EQ(pixelAt(image, p.x, p.y), plotSeriesColour(s)) << series[s].name;
    }
    // The palette has 16 distinct colours (8 hues, then the same darker), then repeats.
    for (std::size_t a = 0; a < 16; ++a)
        for (std::size_t b = a + 1; b < 16; ++b) EXPECT_NE(plotSeriesColour(a), plotSeriesColour(b)) << a << " " << b;
    EXPECT_EQ(plotSeriesColour(16), plotSeriesColour(0));
}

TEST(PlotRender, LinesJoinConsecutivePointsUnlessMarkersOnlyOrBroken) {
    // Horizontal curves, so the line through the midpoint covers its pixel fully.
    const std::vector<PlotSeries> lines = {{"line", {10.0, 1000.0}, {0.1, 0.1}}};
    const std::vector<PlotSeries> markers = {{"markers", {10.0, 1000.0}, {0.1, 0.1}, true}};
    const std::vector<PlotSeries> broken = {{"broken", {10.0, 100.0, 1000.0}, {0.1, -1.0, 0.1}}};
    const glm::ivec2 middle = pixelOf(computePlotFrame(lines, PlotOptions{}), 100.0, 0.1);

    PlotReport report;
    const Image withLines = renderLogLogPlot(lines, PlotOptions{}, &report);
    ASSERT_FALSE(report.legendArea.contains(middle.x, middle.y));
    EXPECT_EQ(pixelAt(withLines, middle.x, middle.y), plotSeriesColour(0));

    const Image withMarkers = renderLogLogPlot(markers, PlotOptions{});
    EXPECT_NE(pixelAt(withMarkers, middle.x, middle.y), plotSeriesColour(0));

    ASSERT_EQ(computePlotFrame(broken, PlotOptions{}).plotArea.left,
              computePlotFrame(lines, PlotOptions{}).plotArea.left);
    const Image withGap = renderLogLogPlot(broken, PlotOptions{}, &report);
    EXPECT_NE(pixelAt(withGap, middle.x, middle.y), plotSeriesColour(0));
    EXPECT_EQ(report.pointsSkipped, 1u);
}

TEST(PlotRender, UndrawablePointsAreSkippedAndCounted) {
    const std::vector<PlotSeries> series = {
        {"a", {1.0, 0.0, -2.0, kNaN, 10.0, kInf}, {1.0, 1.0, 1.0, 1.0, 0.5, 1.0}},
        {"b", {5.0, 6.0, 7.0}, {0.0, -kInf, 0.25}},
    };
    PlotReport report;
    renderLogLogPlot(series, smallOptions(), &report);
    EXPECT_EQ(report.pointsDrawn, 3u);
    EXPECT_EQ(report.pointsSkipped, 6u);
}

TEST(PlotRender, MismatchedSeriesAndTinyImagesAreRejected) {
    EXPECT_THROW(renderLogLogPlot({{"bad", {1.0, 2.0}, {1.0}}}, PlotOptions{}), std::invalid_argument);
    PlotOptions tiny;
    tiny.width = 40;
    tiny.height = 30;
    EXPECT_THROW(renderLogLogPlot({}, tiny), std::invalid_argument);
}

TEST(PlotRender, TitleInkLiesInsideTheTitleArea) {
    PlotOptions options;
    options.title = "relMSE vs time";
    options.xLabel = "wall ms";
    options.yLabel = "relMSE";
    const std::vector<PlotSeries> series = {{"raw", {10.0, 100.0}, {0.1, 0.01}}};
    const Image image = renderLogLogPlot(series, options);
    const PlotFrame frame = computePlotFrame(series, options);
    const PixelRect& title = frame.titleArea;
    ASSERT_FALSE(title.empty());
    EXPECT_LT(title.bottom, frame.plotArea.top);

    // Ink inside the title box, nothing above it (the top margin).
    int inkInTitle = 0;
    for (int y = title.top; y <= title.bottom; ++y)
        for (int x = title.left; x <= title.right; ++x) inkInTitle += isBackground(image, x, y) ? 0 : 1;
    EXPECT_GT(inkInTitle, 50);
    for (int y = 0; y < title.top; ++y)
        for (int x = 0; x < image.width(); ++x) ASSERT_TRUE(isBackground(image, x, y)) << x << "," << y;
    // Ink stays within the title box's columns on its rows.
    for (int y = title.top; y <= title.bottom; ++y)
        for (int x = 0; x < image.width(); ++x)
            if (!title.contains(x, y)) {
                ASSERT_TRUE(isBackground(image, x, y)) << x << "," << y;
            }

    options.title.clear();
    EXPECT_TRUE(computePlotFrame(series, options).titleArea.empty());
}

TEST(PlotRender, LongTitlesShrinkThenAreShortenedToFit) {
    PlotOptions options;
    options.width = 200;
    options.height = 150;
    options.title = "a very long title that certainly does not fit into two hundred pixels";
    const Image image = renderLogLogPlot({}, options);
    const PixelRect title = computePlotFrame({}, options).titleArea;
    ASSERT_FALSE(title.empty());
    EXPECT_GE(title.left, 0);
    EXPECT_LT(title.right, options.width);
    // The last three glyphs are "...": ink only in the bottom rows of the box's tail.
    int tailInk = 0;
    for (int y = title.top; y <= title.bottom; ++y)
        for (int x = title.right - 16; x <= title.right; ++x) tailInk += isBackground(image, x, y) ? 0 : 1;
    EXPECT_GT(tailInk, 0);
    for (int y = title.top; y < title.top + 5; ++y)
        for (int x = title.right - 16; x <= title.right; ++x) EXPECT_TRUE(isBackground(image, x, y)) << x << "," << y;
}

TEST(PlotRender, LegendAvoidsADecreasingCurve) {
    // A curve from top left to bottom right: the legend goes to a free corner.
    PlotSeries curve{"svgf", {}, {}};
    for (double ms = 10.0; ms <= 10000.0; ms *= 1.5) {
        curve.x.push_back(ms);
        curve.y.push_back(10.0 / ms);
    }
    PlotReport report;
    const Image image = renderLogLogPlot({curve}, PlotOptions{}, &report);
    ASSERT_FALSE(report.legendArea.empty());
    const PlotFrame frame = computePlotFrame({curve}, PlotOptions{});
    for (std::size_t i = 0; i < curve.x.size(); ++i) {
        const glm::ivec2 p = pixelOf(frame, curve.x[i], curve.y[i]);
        EXPECT_FALSE(report.legendArea.contains(p.x, p.y)) << i;
        EXPECT_EQ(pixelAt(image, p.x, p.y), plotSeriesColour(0)) << i;
    }
    // The legend shows the series colour (its swatch) and lies in the data area.
    int swatchPixels = 0;
    const PixelRect& legend = report.legendArea;
    for (int y = legend.top; y <= legend.bottom; ++y)
        for (int x = legend.left; x <= legend.right; ++x) swatchPixels += pixelAt(image, x, y) == plotSeriesColour(0);
    EXPECT_GT(swatchPixels, 10);
    EXPECT_TRUE(frame.plotArea.contains(legend.left, legend.top));
    EXPECT_TRUE(frame.plotArea.contains(legend.right, legend.bottom));
}

TEST(PlotRender, IdenticalInputsGiveIdenticalImages) {
    const std::vector<PlotSeries> series = {{"raw", {12.0, 120.0, 1200.0}, {0.3, 0.03, 0.003}},
                                            {"svgf", {30.0, 300.0, 3000.0}, {0.02, 0.004, 7e-4}}};
    PlotOptions options;
    options.title = "determinism";
    const Image a = renderLogLogPlot(series, options);
    const Image b = renderLogLogPlot(series, options);
    for (const char* channel : {"R", "G", "B"})
        EXPECT_EQ(0, std::memcmp(a.channel(channel), b.channel(channel), a.pixelCount() * sizeof(float))) << channel;
}

// ---------------------------------------------------------------------------
// Files

TEST_F(PlotFiles, PngHasTheRequestedSizeAndTheMarkerColour) {
    const std::vector<PlotSeries> series = {{"raw", {10.0, 300.0, 1000.0}, {1.0, 0.02, 0.001}}};
    PlotOptions options;
    options.width = 800;
    options.height = 500;
    const PlotReport report = writeLogLogPlot(dir / "plot.png", series, options);
    EXPECT_EQ(report.pointsDrawn, 3u);

    const DecodedPng png = decodePng(dir / "plot.png");
    ASSERT_EQ(png.width, 800);
    ASSERT_EQ(png.height, 500);
    const glm::ivec2 p = pixelOf(computePlotFrame(series, options), 300.0, 0.02);
    const std::size_t i = (static_cast<std::size_t>(p.y) * png.width + p.x) * 3;
    const vec3 colour = plotSeriesColour(0);
    EXPECT_EQ(png.rgb[i + 0], srgbCode(colour.r));
    EXPECT_EQ(png.rgb[i + 1], srgbCode(colour.g));
    EXPECT_EQ(png.rgb[i + 2], srgbCode(colour.b));
}

TEST_F(PlotFiles, IdenticalInputsGiveIdenticalPngBytes) {
    const std::vector<PlotSeries> series = {{"raw", {12.0, 120.0, 1200.0}, {0.3, 0.03, 0.003}},
                                            {"svgf", {30.0, 300.0, 3000.0}, {0.02, kNaN, 7e-4}}};
    PlotOptions options;
    options.title = "same bytes";
    options.xLabel = "ms";
    writeLogLogPlot(dir / "a.png", series, options);
    writeLogLogPlot(dir / "b.png", series, options);
    const std::vector<unsigned char> a = readBytes(dir / "a.png");
    ASSERT_FALSE(a.empty());
    EXPECT_EQ(a, readBytes(dir / "b.png"));
}

TEST_F(PlotFiles, EmptyPlotsStillWriteAxes) {
    // No series at all, and a series without one drawable point.
    const std::vector<std::vector<PlotSeries>> cases = {{}, {{"nothing", {0.0, kNaN}, {1.0, 1.0}}}};
    for (std::size_t c = 0; c < cases.size(); ++c) {
        const fs::path path = dir / ("empty" + std::to_string(c) + ".png");
        const PlotReport report = writeLogLogPlot(path, cases[c], smallOptions());
        EXPECT_EQ(report.pointsDrawn, 0u) << c;
        EXPECT_EQ(report.pointsSkipped, c == 0 ? 0u : 2u) << c;
        EXPECT_EQ(report.legendArea.empty(), cases[c].empty()) << c;

        const DecodedPng png = decodePng(path);
        ASSERT_EQ(png.width, 480) << c;
        ASSERT_EQ(png.height, 320) << c;
        // The axis frame is drawn: the data area's bottom-left pixel is ink.
        const PlotFrame frame = computePlotFrame(cases[c], smallOptions());
        EXPECT_LT(frame.xDecadeMin, frame.xDecadeMax);
        EXPECT_LT(frame.yDecadeMin, frame.yDecadeMax);
        const std::size_t i = (static_cast<std::size_t>(frame.plotArea.bottom) * png.width + frame.plotArea.left) * 3;
        EXPECT_LT(png.rgb[i], 100) << c;
    }
}

// The SVG for papers: text as text in the one font, a circle with its <title>
// per drawable point (escaped), a polyline per series, categorical x named on
// the axis, undrawable points counted; the same inputs give the same text.
TEST(PlotSvg, PointsCarryTheirTitlesAndTextStaysText) {
    std::vector<PlotSeries> series(2);
    series[0].name = "cornell & co";
    series[0].x = {1.0, 2.0, 3.0};
    series[0].y = {100.0, 0.0, 400.0};  // the middle point is not drawable on a log axis
    series[1].name = "terrain";
    series[1].x = {1.0, 2.0, 3.0};
    series[1].y = {1e4, 2e4, 3e4};
    PlotOptions options;
    options.xLabel = "scheduler.policy";
    options.yLabel = "cycles";
    SvgPlotExtras extras;
    extras.pointTitles = {{"p0000: <a>", "p0001", "p0002"}, {"p0003", "p0004", "p0005"}};
    extras.xCategories = {"fifo", "oldestFirst", "treelet"};
    PlotReport report;
    const std::string svg = renderLogLogPlotSvg(series, options, extras, &report);
    const auto count = [&](const std::string& what) {
        std::size_t n = 0;
        for (std::size_t at = svg.find(what); at != std::string::npos; at = svg.find(what, at + 1)) ++n;
        return n;
    };
    EXPECT_EQ(svg.rfind("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"252.00pt\"", 0), 0u);
    EXPECT_NE(svg.find("font-family:'DejaVu Sans'"), std::string::npos);
    EXPECT_EQ(report.pointsDrawn, 5u);
    EXPECT_EQ(report.pointsSkipped, 1u);
    EXPECT_EQ(count("<circle "), 5u);
    EXPECT_EQ(count("<title>"), 5u);
    EXPECT_NE(svg.find("<title>p0000: &lt;a&gt;</title>"), std::string::npos);
    EXPECT_EQ(svg.find("<title>p0001</title>"), std::string::npos) << "an undrawable point has no circle";
    EXPECT_EQ(count("<polyline "), 1u) << "series 0 breaks at its gap into single points; series 1 is one line";
    for (const char* text : {">oldestFirst</text>", ">scheduler.policy</text>", ">cycles</text>",
                             ">cornell &amp; co</text>", ">terrain</text>", ">10000</text>"})
        EXPECT_NE(svg.find(text), std::string::npos) << text;
    EXPECT_EQ(svg, renderLogLogPlotSvg(series, options, extras));
}
