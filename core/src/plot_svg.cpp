// Log-log (or categorical-x) line plots as SVG for papers: one column wide,
// text as text in one font (kPlotFontFamily), decade ticks with minor ticks,
// the legend below the axes, each point a circle with a <title>.
#include <rtlab/core/plot.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace rtlab {

namespace {

// Two decimals: enough for points on a 252 pt figure, deterministic text.
std::string num(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.2f", v);
    return buf;
}

std::string hexColour(const vec3& linear) {
    const auto encode = [](float c) {
        c = std::clamp(c, 0.f, 1.f);
        const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.f / 2.4f) - 0.055f;
        return static_cast<int>(std::lround(s * 255.f));
    };
    char buf[8];
    std::snprintf(buf, sizeof buf, "#%02x%02x%02x", encode(linear.r), encode(linear.g), encode(linear.b));
    return buf;
}

// Rough width of text in points at `size` (DejaVu Sans averages about 0.62 em):
// only used to keep tick labels apart and to size the legend.
double textWidth(const std::string& text, double size) { return 0.62 * size * static_cast<double>(text.size()); }

}  // namespace

std::string xmlEscape(const std::string& text) {
    std::string out;
    for (char c : text) {
        switch (c) {
            case '&': out += "&amp;"; break;
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '"': out += "&quot;"; break;
            default: out += c;
        }
    }
    return out;
}

std::string renderLogLogPlotSvg(const std::vector<PlotSeries>& series, const PlotOptions& options,
                                const SvgPlotExtras& extras, PlotReport* report) {
    const bool categorical = !extras.xCategories.empty();
    // Step: the data's range; decades enclosing every drawable point.
    double xMin = INFINITY, xMax = -INFINITY, yMin = INFINITY, yMax = -INFINITY;
    PlotReport result;
    const auto drawable = [&](double x, double y) {
        return (categorical ? std::isfinite(x) : isLogPlottable(x)) && isLogPlottable(y);
    };
    for (const PlotSeries& s : series)
        for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
            if (!drawable(s.x[i], s.y[i])) {
                ++result.pointsSkipped;
                continue;
            }
            ++result.pointsDrawn;
            xMin = std::min(xMin, s.x[i]), xMax = std::max(xMax, s.x[i]);
            yMin = std::min(yMin, s.y[i]), yMax = std::max(yMax, s.y[i]);
        }
    int yLo = 0, yHi = 1, xLo = 0, xHi = 1;
    if (result.pointsDrawn > 0) {
        yLo = static_cast<int>(std::floor(std::log10(yMin)));
        yHi = std::max(yLo + 1, static_cast<int>(std::ceil(std::log10(yMax))));
        xLo = static_cast<int>(std::floor(std::log10(xMin)));
        xHi = std::max(xLo + 1, static_cast<int>(std::ceil(std::log10(xMax))));
    }
    const double xFirst = categorical ? 0.5 : 0.0, xLast = categorical ? double(extras.xCategories.size()) + 0.5 : 0.0;

    // Step: the layout, in points: a 252 pt wide figure, axes 170 x 120 pt,
    // the legend's rows below the x label.
    constexpr double kWidth = 252.0, kFont = 7.0, kSmall = 6.0;
    const double left = 40.0, top = options.title.empty() ? 14.0 : 24.0, plotW = 200.0, plotH = 120.0;
    const double axisBottom = top + plotH;
    const double legendTop = axisBottom + 30.0, rowH = 9.0;
    const double height = legendTop + rowH * static_cast<double>(series.size()) + 4.0;
    const auto px = [&](double x) {
        const double t = categorical ? (x - xFirst) / (xLast - xFirst) : (std::log10(x) - xLo) / double(xHi - xLo);
        return left + t * plotW;
    };
    const auto py = [&](double y) { return axisBottom - (std::log10(y) - yLo) / double(yHi - yLo) * plotH; };

    std::string svg;
    svg += "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" + num(kWidth) + "pt\" height=\"" + num(height) +
           "pt\" viewBox=\"0 0 " + num(kWidth) + " " + num(height) + "\" role=\"img\">\n";
    svg += "<style>text{font-family:'" + std::string(kPlotFontFamily) + "',sans-serif;font-size:" + num(kFont) +
           "px;fill:#222}.tick{font-size:" + num(kSmall) +
           "px}.grid{stroke:#e4e4e4;stroke-width:0.4}.axis{stroke:#222;stroke-width:0.6;fill:none}</style>\n";
    svg += "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
    if (!options.title.empty())
        svg += "<text x=\"" + num(left + plotW / 2) + "\" y=\"12\" text-anchor=\"middle\">" + xmlEscape(options.title) +
               "</text>\n";

    // Step: grid and ticks: y decades with minor ticks; x decades or categories.
    for (int e = yLo; e <= yHi; ++e) {
        const double y = py(std::pow(10.0, e));
        svg += "<line class=\"grid\" x1=\"" + num(left) + "\" y1=\"" + num(y) + "\" x2=\"" + num(left + plotW) +
               "\" y2=\"" + num(y) + "\"/>\n";
        svg += "<text class=\"tick\" x=\"" + num(left - 3) + "\" y=\"" + num(y + 2) + "\" text-anchor=\"end\">" +
               xmlEscape(decadeLabel(e)) + "</text>\n";
        if (e < yHi)
            for (int m = 2; m <= 9; ++m) {
                const double ym = py(m * std::pow(10.0, e));
                svg += "<line class=\"axis\" x1=\"" + num(left) + "\" y1=\"" + num(ym) + "\" x2=\"" + num(left + 2) +
                       "\" y2=\"" + num(ym) + "\"/>\n";
            }
    }
    if (categorical) {
        for (std::size_t i = 0; i < extras.xCategories.size(); ++i) {
            const double x = px(double(i + 1));
            svg += "<line class=\"grid\" x1=\"" + num(x) + "\" y1=\"" + num(top) + "\" x2=\"" + num(x) + "\" y2=\"" +
                   num(axisBottom) + "\"/>\n";
            svg += "<text class=\"tick\" x=\"" + num(x) + "\" y=\"" + num(axisBottom + 8) +
                   "\" text-anchor=\"middle\">" + xmlEscape(extras.xCategories[i]) + "</text>\n";
        }
    } else {
        for (int e = xLo; e <= xHi; ++e) {
            const double x = px(std::pow(10.0, e));
            svg += "<line class=\"grid\" x1=\"" + num(x) + "\" y1=\"" + num(top) + "\" x2=\"" + num(x) + "\" y2=\"" +
                   num(axisBottom) + "\"/>\n";
            svg += "<text class=\"tick\" x=\"" + num(x) + "\" y=\"" + num(axisBottom + 8) +
                   "\" text-anchor=\"middle\">" + xmlEscape(decadeLabel(e)) + "</text>\n";
            if (e < xHi)
                for (int m = 2; m <= 9; ++m) {
                    const double xm = px(m * std::pow(10.0, e));
                    svg += "<line class=\"axis\" x1=\"" + num(xm) + "\" y1=\"" + num(axisBottom) + "\" x2=\"" +
                           num(xm) + "\" y2=\"" + num(axisBottom - 2) + "\"/>\n";
                }
        }
    }
    svg += "<rect class=\"axis\" x=\"" + num(left) + "\" y=\"" + num(top) + "\" width=\"" + num(plotW) +
           "\" height=\"" + num(plotH) + "\"/>\n";
    svg += "<text x=\"" + num(left + plotW / 2) + "\" y=\"" + num(axisBottom + 18) + "\" text-anchor=\"middle\">" +
           xmlEscape(options.xLabel) + "</text>\n";
    svg += "<text transform=\"translate(9 " + num(top + plotH / 2) + ") rotate(-90)\" text-anchor=\"middle\">" +
           xmlEscape(options.yLabel) + "</text>\n";

    // Step: each series: its line (broken at undrawable points), its points
    // with their titles, its legend row.
    for (std::size_t k = 0; k < series.size(); ++k) {
        const PlotSeries& s = series[k];
        const std::string colour = hexColour(plotSeriesColour(k));
        svg += "<g class=\"series\" data-series=\"" + std::to_string(k) + "\">\n";
        if (!s.markersOnly) {
            std::string points;
            const auto flush = [&] {
                if (points.find(' ') != std::string::npos)
                    svg += "<polyline fill=\"none\" stroke=\"" + colour + "\" stroke-width=\"1\" points=\"" + points +
                           "\"/>\n";
                points.clear();
            };
            for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
                if (!drawable(s.x[i], s.y[i])) {
                    flush();
                    continue;
                }
                if (!points.empty()) points += ' ';
                points += num(px(s.x[i]));
                points += ',';
                points += num(py(s.y[i]));
            }
            flush();
        }
        for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
            if (!drawable(s.x[i], s.y[i])) continue;
            svg += "<circle cx=\"" + num(px(s.x[i])) + "\" cy=\"" + num(py(s.y[i])) + "\" r=\"1.8\" fill=\"" + colour +
                   "\">";
            if (k < extras.pointTitles.size() && i < extras.pointTitles[k].size())
                svg += "<title>" + xmlEscape(extras.pointTitles[k][i]) + "</title>";
            svg += "</circle>\n";
        }
        // The legend row across the figure's width; a long name gets a smaller
        // font (rsvg, which writes the PDFs, ignores textLength).
        const double y = legendTop + rowH * double(k);
        const double room = kWidth - 26.0, size = std::min(kFont, room / std::max(1.0, textWidth(s.name, 1.0)));
        svg += "<line x1=\"6\" y1=\"" + num(y - 2.5) + "\" x2=\"18\" y2=\"" + num(y - 2.5) + "\" stroke=\"" + colour +
               "\" stroke-width=\"1.2\"/>\n";
        svg += "<text x=\"22\" y=\"" + num(y) + "\" style=\"font-size:" + num(size) + "px\">" + xmlEscape(s.name) +
               "</text>\n";
        svg += "</g>\n";
    }
    svg += "</svg>\n";
    if (report) *report = result;
    return svg;
}

}  // namespace rtlab
