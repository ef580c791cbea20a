#pragma once
// A small, dependency-free log-log line plot drawn into an Image (linear RGB
// "R","G","B") and written as a PNG: e.g. `rtlab converge`'s error (relMSE)
// against wall milliseconds, one curve per method.
//
// Axes span whole decades enclosing every drawable point; a point is drawable
// when both coordinates are finite and > 0. Other points are skipped and
// counted in PlotReport (a curve breaks at a skipped point). Text uses an
// embedded 5x7 bitmap font (printable ASCII; anything else draws as '?').
// Output is deterministic: the same inputs give bit-identical images and PNGs.
#include <rtlab/core/image.hpp>
#include <rtlab/core/math.hpp>

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

namespace rtlab {

struct PlotSeries {
    std::string name;       // legend entry
    std::vector<double> x;  // same length as y (std::invalid_argument otherwise)
    std::vector<double> y;
    bool markersOnly = false;  // no lines between consecutive points
};

struct PlotOptions {
    int width = 960;  // at least 200 x 150 (std::invalid_argument otherwise)
    int height = 640;
    std::string title;   // centred above the plot; none when empty
    std::string xLabel;  // centred below the x tick labels
    std::string yLabel;  // drawn horizontally above the top-left corner of the plot
};

// What only the SVG has.
struct SvgPlotExtras {
    // Per series, one hover text per point (its <title>); missing entries: none.
    std::vector<std::vector<std::string>> pointTitles;
    // Names of categorical x values 1, 2, ... (a linear axis with these labels
    // instead of a log axis); empty for numeric x.
    std::vector<std::string> xCategories;
};

// A pixel rectangle with inclusive bounds; empty when right < left or bottom < top.
struct PixelRect {
    int left = 0;
    int top = 0;
    int right = -1;
    int bottom = -1;

    bool empty() const { return right < left || bottom < top; }
    bool contains(int x, int y) const { return x >= left && x <= right && y >= top && y <= bottom; }
};

// Where things go on the canvas, and the data -> pixel mapping.
struct PlotFrame {
    // Data area. Its border pixels carry the axis frame; the axis range's
    // bounds map to the centres of its outermost pixels.
    PixelRect plotArea;
    PixelRect titleArea;  // empty when there is no title
    // Axis ranges in decades: x spans 10^xDecadeMin .. 10^xDecadeMax, etc.
    int xDecadeMin = 0;
    int xDecadeMax = 1;
    int yDecadeMin = 0;
    int yDecadeMax = 1;
    int textScale = 1;  // integer scale of the 5x7 font for labels

    // Continuous pixel position of a data point (x right, y down; pixel (i, j)
    // covers [i, i+1) x [j, j+1)). Only meaningful for drawable points.
    glm::dvec2 toPixel(double x, double y) const;
};

struct PlotReport {
    std::size_t pointsDrawn = 0;
    std::size_t pointsSkipped = 0;  // non-positive or non-finite on a log axis
    PixelRect legendArea;           // empty when there is no series
};

// True when `value` can be placed on a log axis (finite and > 0).
bool isLogPlottable(double value);
// Decade tick label: "0.01" .. "10000" inside that range, else "1e-3", "1e5".
std::string decadeLabel(int exponent);
// The colour (linear RGB) of series `seriesIndex`: a fixed palette of 8 hues,
// then the same 8 darker, cycled after 16.
vec3 plotSeriesColour(std::size_t seriesIndex);

// The layout and axis ranges renderLogLogPlot uses for these inputs.
PlotFrame computePlotFrame(const std::vector<PlotSeries>& series, const PlotOptions& options);

// Draws the plot (white background; axes even when nothing is drawable).
Image renderLogLogPlot(const std::vector<PlotSeries>& series, const PlotOptions& options, PlotReport* report = nullptr);
// renderLogLogPlot, then writePng (atomic). Throws InputError naming the file
// when it cannot be written.
PlotReport writeLogLogPlot(const std::filesystem::path& png, const std::vector<PlotSeries>& series,
                           const PlotOptions& options);

// The same plot as vector graphics for a paper (plot_svg.cpp): an SVG of one
// column's width (3.5 in = 252 pt), text kept as text in kPlotFontFamily (the
// one place the font is set; `rtlab report` embeds it when converting to
// PDF), labelled axes, the legend below the plot, and each drawable point a
// circle carrying its extras.pointTitles entry as <title> (shown on hover). The
// size is fixed (width and height are the PNG's); the height grows with the
// legend's rows. Deterministic text.
inline constexpr const char* kPlotFontFamily = "DejaVu Sans";
// Text with &, <, >, " escaped for XML and HTML (the SVG's text, the report's page).
std::string xmlEscape(const std::string& text);
std::string renderLogLogPlotSvg(const std::vector<PlotSeries>& series, const PlotOptions& options,
                                const SvgPlotExtras& extras = {}, PlotReport* report = nullptr);

}  // namespace rtlab
