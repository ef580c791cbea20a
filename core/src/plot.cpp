// Log-log line plots drawn on a linear-RGB canvas: decade axes, grid, curves
// with markers (anti-aliased by signed distance), a legend placed where it
// covers the least ink, and text in an embedded 5x7 bitmap font.
#include <rtlab/core/plot.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

namespace rtlab {

namespace {

// ---------------------------------------------------------------------------
// Font: 5x7 glyphs for ASCII 32..126, one byte per row (top first), bit 4 is
// the leftmost column.

constexpr int kGlyphWidth = 5;
constexpr int kGlyphHeight = 7;
constexpr int kGlyphAdvance = 6;  // glyph plus one column of spacing
constexpr char kFirstGlyph = ' ';
constexpr char kLastGlyph = '~';

constexpr std::uint8_t kFont5x7[95][kGlyphHeight] = {
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00},  // ' '
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x04},  // !
    {0x0A, 0x0A, 0x0A, 0x00, 0x00, 0x00, 0x00},  // "
    {0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A},  // #
    {0x04, 0x0F, 0x14, 0x0E, 0x05, 0x1E, 0x04},  // $
    {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03},  // %
    {0x0C, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0D},  // &
    {0x0C, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00},  // '
    {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02},  // (
    {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08},  // )
    {0x00, 0x04, 0x15, 0x0E, 0x15, 0x04, 0x00},  // *
    {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00},  // +
    {0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08},  // ,
    {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00},  // -
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C},  // .
    {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00},  // /
    {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E},  // 0
    {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E},  // 1
    {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F},  // 2
    {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E},  // 3
    {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02},  // 4
    {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E},  // 5
    {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E},  // 6
    {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08},  // 7
    {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E},  // 8
    {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C},  // 9
    {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00},  // :
    {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x04, 0x08},  // ;
    {0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02},  // <
    {0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00},  // =
    {0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08},  // >
    {0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04},  // ?
    {0x0E, 0x11, 0x01, 0x0D, 0x15, 0x15, 0x0E},  // @
    {0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11},  // A
    {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E},  // B
    {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E},  // C
    {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C},  // D
    {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F},  // E
    {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10},  // F
    {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F},  // G
    {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11},  // H
    {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E},  // I
    {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C},  // J
    {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11},  // K
    {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F},  // L
    {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11},  // M
    {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11},  // N
    {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E},  // O
    {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10},  // P
    {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D},  // Q
    {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11},  // R
    {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E},  // S
    {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04},  // T
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E},  // U
    {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04},  // V
    {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A},  // W
    {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11},  // X
    {0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04},  // Y
    {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F},  // Z
    {0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E},  // [
    {0x00, 0x10, 0x08, 0x04, 0x02, 0x01, 0x00},  // backslash
    {0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E},  // ]
    {0x04, 0x0A, 0x11, 0x00, 0x00, 0x00, 0x00},  // ^
    {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F},  // _
    {0x08, 0x04, 0x02, 0x00, 0x00, 0x00, 0x00},  // `
    {0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F},  // a
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E},  // b
    {0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E},  // c
    {0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F},  // d
    {0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E},  // e
    {0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08},  // f
    {0x00, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x0E},  // g (drawn with its descender below)
    {0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11},  // h
    {0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E},  // i
    {0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C},  // j (drawn with its descender below)
    {0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12},  // k
    {0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E},  // l
    {0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11},  // m
    {0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11},  // n
    {0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E},  // o
    {0x00, 0x00, 0x1E, 0x11, 0x1E, 0x10, 0x10},  // p (drawn with its descender below)
    {0x00, 0x00, 0x0D, 0x13, 0x0F, 0x01, 0x01},  // q (drawn with its descender below)
    {0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10},  // r
    {0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E},  // s
    {0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06},  // t
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D},  // u
    {0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04},  // v
    {0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A},  // w
    {0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11},  // x
    {0x00, 0x00, 0x11, 0x11, 0x0F, 0x01, 0x0E},  // y (drawn with its descender below)
    {0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F},  // z
    {0x02, 0x04, 0x04, 0x08, 0x04, 0x04, 0x02},  // {
    {0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04},  // |
    {0x08, 0x04, 0x04, 0x02, 0x04, 0x04, 0x08},  // }
    {0x00, 0x00, 0x08, 0x15, 0x02, 0x00, 0x00},  // ~
};

// Lower-case letters with descenders: 9 rows, the last two below the baseline
// (the x-height rows 2..6 match the 7-row letters).
constexpr int kDescenderHeight = 9;
struct DescenderGlyph {
    char character;
    std::uint8_t rows[kDescenderHeight];
};
constexpr DescenderGlyph kDescenderGlyphs[] = {
    {'g', {0x00, 0x00, 0x0F, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x0E}},
    {'j', {0x02, 0x00, 0x06, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}},
    {'p', {0x00, 0x00, 0x1E, 0x11, 0x11, 0x11, 0x1E, 0x10, 0x10}},
    {'q', {0x00, 0x00, 0x0F, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x01}},
    {'y', {0x00, 0x00, 0x11, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x0E}},
};

// The rows of a glyph (7, or 9 with a descender); '?' for non-printable characters.
std::span<const std::uint8_t> glyphRows(char character) {
    for (const DescenderGlyph& glyph : kDescenderGlyphs)
        if (glyph.character == character) return {glyph.rows, kDescenderHeight};
    const char printable = character < kFirstGlyph || character > kLastGlyph ? '?' : character;
    return {kFont5x7[printable - kFirstGlyph], kGlyphHeight};
}

int textWidth(std::string_view text, int scale) {
    return text.empty() ? 0 : (static_cast<int>(text.size()) * kGlyphAdvance - 1) * scale;
}

// Height of capitals and digits; placement is by this height.
int textHeight(int scale) { return kGlyphHeight * scale; }
// Height including descenders: the room a line of free text takes.
int lineHeight(int scale) { return kDescenderHeight * scale; }

// ---------------------------------------------------------------------------
// Colours (given in sRGB, stored linear so writePng shows them as given).

vec3 fromSrgb8(int r, int g, int b) {
    return {srgbToLinear(static_cast<float>(r) / 255.f), srgbToLinear(static_cast<float>(g) / 255.f),
            srgbToLinear(static_cast<float>(b) / 255.f)};
}

// Tableau-style categorical palette (grey and olive left out: grey is the grid's).
constexpr int kPaletteSrgb8[8][3] = {{31, 119, 180},  {255, 127, 14}, {44, 160, 44},   {214, 39, 40},
                                     {148, 103, 189}, {140, 86, 75},  {227, 119, 194}, {23, 190, 207}};

const vec3 kBackground = fromSrgb8(255, 255, 255);
const vec3 kInk = fromSrgb8(34, 34, 34);
const vec3 kMajorGrid = fromSrgb8(221, 221, 221);
const vec3 kMinorGrid = fromSrgb8(242, 242, 242);
const vec3 kLegendBorder = fromSrgb8(190, 190, 190);
constexpr float kLegendOpacity = 0.88f;

// ---------------------------------------------------------------------------
// Canvas: linear RGB, top row first, with clipped "over" blending.

class Canvas {
public:
    Canvas(int width, int height, vec3 background)
        : width_(width), height_(height), pixels_(static_cast<std::size_t>(width) * height, background) {}

    int width() const { return width_; }
    int height() const { return height_; }

    void blend(int x, int y, vec3 colour, float alpha) {
        if (x < 0 || y < 0 || x >= width_ || y >= height_ || alpha <= 0.f) return;
        vec3& pixel = pixels_[static_cast<std::size_t>(y) * width_ + x];
        pixel = alpha >= 1.f ? colour : pixel * (1.f - alpha) + colour * alpha;
    }

    void fill(const PixelRect& rect, vec3 colour, float alpha = 1.f) {
        for (int y = std::max(rect.top, 0); y <= std::min(rect.bottom, height_ - 1); ++y)
            for (int x = std::max(rect.left, 0); x <= std::min(rect.right, width_ - 1); ++x) blend(x, y, colour, alpha);
    }

    // Text in the 5x7 font, each font pixel an s x s block; (left, top) is the
    // first glyph's top-left corner; descenders reach 2 font rows lower.
    void text(std::string_view text, int left, int top, int scale, vec3 colour) {
        int penX = left;
        for (const char character : text) {
            const std::span<const std::uint8_t> rows = glyphRows(character);
            for (int row = 0; row < static_cast<int>(rows.size()); ++row)
                for (int column = 0; column < kGlyphWidth; ++column)
                    if ((rows[row] >> (kGlyphWidth - 1 - column)) & 1u) {
                        const int x = penX + column * scale;
                        const int y = top + row * scale;
                        fill({x, y, x + scale - 1, y + scale - 1}, colour);
                    }
            penX += kGlyphAdvance * scale;
        }
    }

    Image toImage() const {
        Image image(width_, height_);
        image.addRgbLayer("", pixels_);
        return image;
    }

private:
    int width_;
    int height_;
    std::vector<vec3> pixels_;
};

// ---------------------------------------------------------------------------
// Coverage of one curve (lines + markers): shapes combine by maximum, so a
// joint between two segments is not blended twice; then one composite.

enum class MarkerShape { Circle, Square, Diamond };
constexpr MarkerShape kMarkerShapes[3] = {MarkerShape::Circle, MarkerShape::Square, MarkerShape::Diamond};

class CoverageMask {
public:
    CoverageMask(int width, int height)
        : width_(width), height_(height), coverage_(static_cast<std::size_t>(width) * height, 0.f) {}

    // A 2*halfWidth wide line from a to b with round caps.
    void addSegment(glm::dvec2 a, glm::dvec2 b, double halfWidth) {
        const glm::dvec2 ab = b - a;
        const double lengthSquared = glm::dot(ab, ab);
        const PixelRect bounds = boundsOf(glm::min(a, b) - halfWidth, glm::max(a, b) + halfWidth);
        rasterize(bounds, [&](glm::dvec2 p) {
            const double along = lengthSquared > 0.0 ? std::clamp(glm::dot(p - a, ab) / lengthSquared, 0.0, 1.0) : 0.0;
            return glm::length(p - (a + ab * along)) - halfWidth;
        });
    }

    void addMarker(glm::dvec2 centre, MarkerShape shape, double radius) {
        const PixelRect bounds = boundsOf(centre - radius * 1.3, centre + radius * 1.3);
        rasterize(bounds, [&](glm::dvec2 p) {
            const glm::dvec2 d = glm::abs(p - centre);
            switch (shape) {
                case MarkerShape::Square: return std::max(d.x, d.y) - radius * 0.85;
                case MarkerShape::Diamond: return (d.x + d.y - radius * 1.3) / std::sqrt(2.0);
                case MarkerShape::Circle: break;
            }
            return glm::length(d) - radius;
        });
    }

    void compositeOnto(Canvas& canvas, vec3 colour) const {
        forEachTouched([&](int x, int y, float coverage) { canvas.blend(x, y, colour, coverage); });
    }

    // occupancy = max(occupancy, coverage), for placing the legend.
    void accumulateInto(std::vector<float>& occupancy) const {
        forEachTouched([&](int x, int y, float coverage) {
            float& cell = occupancy[static_cast<std::size_t>(y) * width_ + x];
            cell = std::max(cell, coverage);
        });
    }

    void clear() {
        forEachTouched([&](int x, int y, float) { coverage_[static_cast<std::size_t>(y) * width_ + x] = 0.f; });
        touched_ = PixelRect{};
    }

private:
    PixelRect boundsOf(glm::dvec2 lo, glm::dvec2 hi) const {
        return {std::max(0, static_cast<int>(std::floor(lo.x)) - 1),
                std::max(0, static_cast<int>(std::floor(lo.y)) - 1),
                std::min(width_ - 1, static_cast<int>(std::ceil(hi.x)) + 1),
                std::min(height_ - 1, static_cast<int>(std::ceil(hi.y)) + 1)};
    }

    // Coverage of each pixel from the signed distance (pixels) of its centre
    // to the shape: 1 inside by half a pixel, 0 outside by half a pixel.
    template <class SignedDistance>
    void rasterize(const PixelRect& bounds, SignedDistance signedDistance) {
        if (bounds.empty()) return;
        for (int y = bounds.top; y <= bounds.bottom; ++y)
            for (int x = bounds.left; x <= bounds.right; ++x) {
                const double distance = signedDistance(glm::dvec2(x + 0.5, y + 0.5));
                const float coverage = static_cast<float>(std::clamp(0.5 - distance, 0.0, 1.0));
                float& cell = coverage_[static_cast<std::size_t>(y) * width_ + x];
                cell = std::max(cell, coverage);
            }
        touched_ = touched_.empty()
                       ? bounds
                       : PixelRect{std::min(touched_.left, bounds.left), std::min(touched_.top, bounds.top),
                                   std::max(touched_.right, bounds.right), std::max(touched_.bottom, bounds.bottom)};
    }

    template <class Visit>
    void forEachTouched(Visit visit) const {
        if (touched_.empty()) return;
        for (int y = touched_.top; y <= touched_.bottom; ++y)
            for (int x = touched_.left; x <= touched_.right; ++x) {
                const float coverage = coverage_[static_cast<std::size_t>(y) * width_ + x];
                if (coverage > 0.f) visit(x, y, coverage);
            }
    }

    int width_;
    int height_;
    std::vector<float> coverage_;
    PixelRect touched_;
};

// ---------------------------------------------------------------------------
// Decades.

// 10^exponent, correctly rounded (strtod is; std::pow need not be).
double powerOfTen(int exponent) { return std::strtod(("1e" + std::to_string(exponent)).c_str(), nullptr); }

// Largest e with 10^e <= value (value finite and > 0).
int decadeFloor(double value) {
    int exponent = static_cast<int>(std::floor(std::log10(value)));
    if (powerOfTen(exponent) > value) --exponent;
    else if (powerOfTen(exponent + 1) <= value) ++exponent;
    return exponent;
}

// Smallest e with 10^e >= value.
int decadeCeil(double value) {
    const int exponent = decadeFloor(value);
    return powerOfTen(exponent) == value ? exponent : exponent + 1;
}

struct DecadeRange {
    int min;
    int max;
};

// Whole decades enclosing `values`; one extra decade each side when they are
// all equal; `fallback` when there are none.
DecadeRange enclosingDecades(const std::vector<double>& values, DecadeRange fallback) {
    if (values.empty()) return fallback;
    const auto [lowest, highest] = std::minmax_element(values.begin(), values.end());
    DecadeRange range{decadeFloor(*lowest), decadeCeil(*highest)};
    if (*lowest == *highest) {
        --range.min;
        ++range.max;
    }
    return range;
}

// Smallest label stride (in decades) of the form 1, 2, 5, 10, 20, 50, ...
// that keeps labels `neededPixels` apart.
int labelStride(double pixelsPerDecade, int neededPixels) {
    for (int power = 1;; power *= 10)
        for (const int step : {1, 2, 5})
            if (step * power * pixelsPerDecade >= neededPixels) return step * power;
}

bool isLabelled(int exponent, int stride) { return ((exponent % stride) + stride) % stride == 0; }

// ---------------------------------------------------------------------------
// Layout.

constexpr int kMinWidth = 200;
constexpr int kMinHeight = 150;
constexpr int kMinPlotSide = 32;
constexpr double kMinGridSpacing = 6.0;    // pixels between decade grid lines, else only labelled ones
constexpr double kMinMinorSpacing = 40.0;  // pixels per decade needed for minor ticks at 2..9

// Sizes derived from the text scale s.
struct Metrics {
    int margin;      // around the whole figure
    int gap;         // between neighbouring elements
    int tickLength;  // major ticks (minor: half)
    int frameWidth;  // axis frame and ticks
    double lineHalfWidth;
    double markerRadius;
};

Metrics metricsFor(int scale) {
    const int thickness = std::max(1, scale / 2);
    return {6 * scale, 4 * scale, 4 * scale, thickness, static_cast<double>(thickness), 1.5 + 1.25 * scale};
}

struct Layout {
    PlotFrame frame;
    Metrics metrics;
    std::string title;  // options.title, shortened with "..." if it cannot fit
    int titleScale = 1;
    int yLabelTop = 0;
    int xTickLabelTop = 0;
    int xLabelTop = 0;
    int xLabelStride = 1;
    int yLabelStride = 1;
};

double pixelsPerXDecade(const PlotFrame& frame) {
    return static_cast<double>(frame.plotArea.right - frame.plotArea.left) / (frame.xDecadeMax - frame.xDecadeMin);
}

double pixelsPerYDecade(const PlotFrame& frame) {
    return static_cast<double>(frame.plotArea.bottom - frame.plotArea.top) / (frame.yDecadeMax - frame.yDecadeMin);
}

double xPixelOfLog(const PlotFrame& frame, double log10x) {
    return frame.plotArea.left + 0.5 + (log10x - frame.xDecadeMin) * pixelsPerXDecade(frame);
}

double yPixelOfLog(const PlotFrame& frame, double log10y) {
    return frame.plotArea.bottom + 0.5 - (log10y - frame.yDecadeMin) * pixelsPerYDecade(frame);
}

bool isDrawable(const PlotSeries& series, std::size_t i) {
    return isLogPlottable(series.x[i]) && isLogPlottable(series.y[i]);
}

Layout computeLayout(const std::vector<PlotSeries>& series, const PlotOptions& options) {
    // Check the inputs.
    if (options.width < kMinWidth || options.height < kMinHeight)
        throw std::invalid_argument("plot size " + std::to_string(options.width) + "x" +
                                    std::to_string(options.height) + " is below the minimum " +
                                    std::to_string(kMinWidth) + "x" + std::to_string(kMinHeight));
    for (const PlotSeries& curve : series)
        if (curve.x.size() != curve.y.size())
            throw std::invalid_argument("plot series '" + curve.name + "' has " + std::to_string(curve.x.size()) +
                                        " x values but " + std::to_string(curve.y.size()) + " y values");

    // Axis ranges from the drawable points.
    std::vector<double> xs;
    std::vector<double> ys;
    for (const PlotSeries& curve : series)
        for (std::size_t i = 0; i < curve.x.size(); ++i)
            if (isDrawable(curve, i)) {
                xs.push_back(curve.x[i]);
                ys.push_back(curve.y[i]);
            }
    Layout layout;
    PlotFrame& frame = layout.frame;
    const DecadeRange xRange = enclosingDecades(xs, {0, 3});
    const DecadeRange yRange = enclosingDecades(ys, {-3, 0});
    frame.xDecadeMin = xRange.min;
    frame.xDecadeMax = xRange.max;
    frame.yDecadeMin = yRange.min;
    frame.yDecadeMax = yRange.max;

    // Sizes.
    const int width = options.width;
    const int height = options.height;
    const int scale = frame.textScale = std::max(1, std::min(width, height) / 320);
    const Metrics& m = layout.metrics = metricsFor(scale);
    const int charHeight = textHeight(scale);

    // Horizontal: y tick labels on the left; half an x tick label may stick
    // out at either end of the x axis.
    int yTickLabelWidth = 0;
    for (int e = frame.yDecadeMin; e <= frame.yDecadeMax; ++e)
        yTickLabelWidth = std::max(yTickLabelWidth, textWidth(decadeLabel(e), scale));
    frame.plotArea.left = std::max(m.margin + yTickLabelWidth + m.tickLength + m.gap + m.frameWidth,
                                   m.margin + textWidth(decadeLabel(frame.xDecadeMin), scale) / 2);
    frame.plotArea.right = width - 1 - (m.margin + textWidth(decadeLabel(frame.xDecadeMax), scale) / 2);

    // Vertical: title, y label row, plot, x tick labels, x label.
    int top = m.margin;
    if (!options.title.empty()) {
        layout.titleScale = scale + 1;
        const int titleRoom = width - 2 * m.margin;
        while (layout.titleScale > 1 && textWidth(options.title, layout.titleScale) > titleRoom) --layout.titleScale;
        layout.title = options.title;
        if (textWidth(layout.title, layout.titleScale) > titleRoom) {
            const int fittingCharacters = (titleRoom / layout.titleScale + 1) / kGlyphAdvance;
            layout.title.resize(static_cast<std::size_t>(std::max(fittingCharacters - 3, 0)));
            layout.title += "...";
        }
        const int titleWidth = textWidth(layout.title, layout.titleScale);
        const int centred = (frame.plotArea.left + frame.plotArea.right + 1 - titleWidth) / 2;
        const int titleLeft = std::max(m.margin, std::min(centred, width - m.margin - titleWidth));
        frame.titleArea = {titleLeft, top, titleLeft + titleWidth - 1, top + lineHeight(layout.titleScale) - 1};
        top += lineHeight(layout.titleScale) + m.gap;
    }
    if (!options.yLabel.empty()) {
        layout.yLabelTop = top;
        top += lineHeight(scale) + m.gap;
    }
    frame.plotArea.top = std::max(top, m.margin + charHeight / 2 + 1);  // room for the top y tick label
    layout.xLabelTop = height - m.margin - (options.xLabel.empty() ? 0 : lineHeight(scale));
    layout.xTickLabelTop = layout.xLabelTop - (options.xLabel.empty() ? 0 : m.gap) - charHeight;
    frame.plotArea.bottom = layout.xTickLabelTop - m.gap - m.tickLength - m.frameWidth;

    if (frame.plotArea.right - frame.plotArea.left < kMinPlotSide ||
        frame.plotArea.bottom - frame.plotArea.top < kMinPlotSide)
        throw std::invalid_argument("plot size " + std::to_string(width) + "x" + std::to_string(height) +
                                    " leaves no room for the data area next to its labels");

    // Label strides: x labels a few characters apart, y labels two rows apart.
    int xTickLabelWidth = 0;
    for (int e = frame.xDecadeMin; e <= frame.xDecadeMax; ++e)
        xTickLabelWidth = std::max(xTickLabelWidth, textWidth(decadeLabel(e), scale));
    layout.xLabelStride = labelStride(pixelsPerXDecade(frame), xTickLabelWidth + 3 * kGlyphAdvance * scale);
    layout.yLabelStride = labelStride(pixelsPerYDecade(frame), 2 * charHeight);
    return layout;
}

// ---------------------------------------------------------------------------
// Drawing steps.

// Light grid lines at decades (and at 2..9 when decades are wide enough).
void drawGrid(Canvas& canvas, const Layout& layout) {
    const PlotFrame& frame = layout.frame;
    const PixelRect& area = frame.plotArea;
    const auto verticalLine = [&](double log10x, vec3 colour) {
        const int column = static_cast<int>(std::floor(xPixelOfLog(frame, log10x)));
        canvas.fill({column, area.top, column, area.bottom}, colour);
    };
    const auto horizontalLine = [&](double log10y, vec3 colour) {
        const int row = static_cast<int>(std::floor(yPixelOfLog(frame, log10y)));
        canvas.fill({area.left, row, area.right, row}, colour);
    };

    // Minor lines first, so decades stay visible on top.
    if (pixelsPerXDecade(frame) >= kMinMinorSpacing)
        for (int e = frame.xDecadeMin; e < frame.xDecadeMax; ++e)
            for (int mantissa = 2; mantissa <= 9; ++mantissa) verticalLine(e + std::log10(mantissa), kMinorGrid);
    if (pixelsPerYDecade(frame) >= kMinMinorSpacing)
        for (int e = frame.yDecadeMin; e < frame.yDecadeMax; ++e)
            for (int mantissa = 2; mantissa <= 9; ++mantissa) horizontalLine(e + std::log10(mantissa), kMinorGrid);

    for (int e = frame.xDecadeMin + 1; e < frame.xDecadeMax; ++e)
        if (pixelsPerXDecade(frame) >= kMinGridSpacing || isLabelled(e, layout.xLabelStride))
            verticalLine(e, kMajorGrid);
    for (int e = frame.yDecadeMin + 1; e < frame.yDecadeMax; ++e)
        if (pixelsPerYDecade(frame) >= kMinGridSpacing || isLabelled(e, layout.yLabelStride))
            horizontalLine(e, kMajorGrid);
}

// Axis frame around the data area, outward ticks, decade labels.
void drawAxes(Canvas& canvas, const Layout& layout) {
    const PlotFrame& frame = layout.frame;
    const PixelRect& area = frame.plotArea;
    const Metrics& m = layout.metrics;
    const int scale = frame.textScale;
    const int outset = m.frameWidth - 1;

    // Frame: the border pixels of the data area, thickened outward.
    canvas.fill({area.left - outset, area.top - outset, area.right + outset, area.top}, kInk);
    canvas.fill({area.left - outset, area.bottom, area.right + outset, area.bottom + outset}, kInk);
    canvas.fill({area.left - outset, area.top - outset, area.left, area.bottom + outset}, kInk);
    canvas.fill({area.right, area.top - outset, area.right + outset, area.bottom + outset}, kInk);

    // Ticks below the x axis.
    const int xTickTop = area.bottom + m.frameWidth;
    const auto xTick = [&](double log10x, int length) {
        const int column = static_cast<int>(std::floor(xPixelOfLog(frame, log10x)));
        canvas.fill({column - outset / 2, xTickTop, column + (outset + 1) / 2, xTickTop + length - 1}, kInk);
        return column;
    };
    if (pixelsPerXDecade(frame) >= kMinMinorSpacing)
        for (int e = frame.xDecadeMin; e < frame.xDecadeMax; ++e)
            for (int mantissa = 2; mantissa <= 9; ++mantissa) xTick(e + std::log10(mantissa), m.tickLength / 2);
    for (int e = frame.xDecadeMin; e <= frame.xDecadeMax; ++e) {
        const bool labelled = isLabelled(e, layout.xLabelStride);
        if (!labelled && pixelsPerXDecade(frame) < kMinGridSpacing) continue;
        const int column = xTick(e, labelled ? m.tickLength : m.tickLength / 2);
        if (!labelled) continue;
        const std::string label = decadeLabel(e);
        canvas.text(label, column + 1 - textWidth(label, scale) / 2, layout.xTickLabelTop, scale, kInk);
    }

    // Ticks left of the y axis.
    const int yTickRight = area.left - m.frameWidth;
    const auto yTick = [&](double log10y, int length) {
        const int row = static_cast<int>(std::floor(yPixelOfLog(frame, log10y)));
        canvas.fill({yTickRight - length + 1, row - outset / 2, yTickRight, row + (outset + 1) / 2}, kInk);
        return row;
    };
    if (pixelsPerYDecade(frame) >= kMinMinorSpacing)
        for (int e = frame.yDecadeMin; e < frame.yDecadeMax; ++e)
            for (int mantissa = 2; mantissa <= 9; ++mantissa) yTick(e + std::log10(mantissa), m.tickLength / 2);
    for (int e = frame.yDecadeMin; e <= frame.yDecadeMax; ++e) {
        const bool labelled = isLabelled(e, layout.yLabelStride);
        if (!labelled && pixelsPerYDecade(frame) < kMinGridSpacing) continue;
        const int row = yTick(e, labelled ? m.tickLength : m.tickLength / 2);
        if (!labelled) continue;
        const std::string label = decadeLabel(e);
        const int labelRight = yTickRight - m.tickLength - m.gap;
        canvas.text(label, labelRight - textWidth(label, scale) + 1, row + 1 - textHeight(scale) / 2, scale, kInk);
    }
}

// One curve per series: lines between consecutive drawable points (broken at
// skipped ones) and a marker at each drawable point.
void drawSeries(Canvas& canvas, const Layout& layout, const std::vector<PlotSeries>& series, PlotReport& report,
                std::vector<float>& occupancy) {
    const PlotFrame& frame = layout.frame;
    CoverageMask mask(canvas.width(), canvas.height());
    for (std::size_t s = 0; s < series.size(); ++s) {
        const PlotSeries& curve = series[s];
        glm::dvec2 previous(0.0);
        bool joinToPrevious = false;
        for (std::size_t i = 0; i < curve.x.size(); ++i) {
            if (!isDrawable(curve, i)) {
                ++report.pointsSkipped;
                joinToPrevious = false;
                continue;
            }
            ++report.pointsDrawn;
            const glm::dvec2 point = frame.toPixel(curve.x[i], curve.y[i]);
            if (joinToPrevious) mask.addSegment(previous, point, layout.metrics.lineHalfWidth);
            mask.addMarker(point, kMarkerShapes[s % 3], layout.metrics.markerRadius);
            previous = point;
            joinToPrevious = !curve.markersOnly;
        }
        mask.compositeOnto(canvas, plotSeriesColour(s));
        mask.accumulateInto(occupancy);
        mask.clear();
    }
}

// Legend box in the data area's corner that covers the least curve ink
// (preferring top right, top left, bottom left, bottom right on ties).
PixelRect drawLegend(Canvas& canvas, const Layout& layout, const std::vector<PlotSeries>& series,
                     const std::vector<float>& occupancy) {
    const PlotFrame& frame = layout.frame;
    const PixelRect& area = frame.plotArea;
    const Metrics& m = layout.metrics;
    const int scale = frame.textScale;
    const int charHeight = textHeight(scale);
    const int markerExtent = static_cast<int>(std::ceil(m.markerRadius));

    // Box size.
    int nameWidth = 0;
    for (const PlotSeries& curve : series) nameWidth = std::max(nameWidth, textWidth(curve.name, scale));
    const int padding = m.gap;
    const int rowHeight = std::max(charHeight, 2 * markerExtent) + m.gap;
    const int swatchWidth = 8 * scale + 2 * markerExtent;
    const int boxWidth = 2 * padding + swatchWidth + m.gap + nameWidth;
    const int boxHeight = 2 * padding + static_cast<int>(series.size()) * rowHeight - m.gap;

    // Corner with the least ink underneath.
    const int inset = m.gap + markerExtent;
    const int leftX = area.left + inset;
    const int rightX = area.right - inset - boxWidth + 1;
    const int topY = area.top + inset;
    const int bottomY = area.bottom - inset - boxHeight + 1;
    const std::array<std::array<int, 2>, 4> corners = {
        {{rightX, topY}, {leftX, topY}, {leftX, bottomY}, {rightX, bottomY}}};
    PixelRect best;
    double bestInk = 0.0;
    for (const auto& [left, top] : corners) {
        const PixelRect box{left, top, left + boxWidth - 1, top + boxHeight - 1};
        double ink = 0.0;
        for (int y = std::max(box.top, 0); y <= std::min(box.bottom, canvas.height() - 1); ++y)
            for (int x = std::max(box.left, 0); x <= std::min(box.right, canvas.width() - 1); ++x)
                ink += occupancy[static_cast<std::size_t>(y) * canvas.width() + x];
        if (best.empty() || ink < bestInk) {
            best = box;
            bestInk = ink;
        }
    }

    // Background, border, then one row per series: swatch and name.
    canvas.fill(best, kBackground, kLegendOpacity);
    const int border = m.frameWidth - 1;
    canvas.fill({best.left, best.top, best.right, best.top + border}, kLegendBorder);
    canvas.fill({best.left, best.bottom - border, best.right, best.bottom}, kLegendBorder);
    canvas.fill({best.left, best.top, best.left + border, best.bottom}, kLegendBorder);
    canvas.fill({best.right - border, best.top, best.right, best.bottom}, kLegendBorder);
    CoverageMask swatch(canvas.width(), canvas.height());
    for (std::size_t s = 0; s < series.size(); ++s) {
        const int rowTop = best.top + padding + static_cast<int>(s) * rowHeight;
        const double centreY = rowTop + rowHeight / 2 - m.gap / 2 + 0.5;
        const double swatchLeft = best.left + padding + 0.5;
        const double swatchRight = swatchLeft + swatchWidth - 1;
        if (!series[s].markersOnly) swatch.addSegment({swatchLeft, centreY}, {swatchRight, centreY}, m.lineHalfWidth);
        swatch.addMarker({std::floor((swatchLeft + swatchRight) / 2) + 0.5, centreY}, kMarkerShapes[s % 3],
                         m.markerRadius);
        swatch.compositeOnto(canvas, plotSeriesColour(s));
        swatch.clear();
        const int textTop = static_cast<int>(centreY) - charHeight / 2;
        canvas.text(series[s].name, best.left + padding + swatchWidth + m.gap, textTop, scale, kInk);
    }
    return best;
}

// Title above, x label below, y label (horizontal) above the data area's top-left.
void drawLabels(Canvas& canvas, const Layout& layout, const PlotOptions& options) {
    const PlotFrame& frame = layout.frame;
    const int scale = frame.textScale;
    if (!layout.title.empty())
        canvas.text(layout.title, frame.titleArea.left, frame.titleArea.top, layout.titleScale, kInk);
    if (!options.xLabel.empty()) {
        const int centred = (frame.plotArea.left + frame.plotArea.right + 1 - textWidth(options.xLabel, scale)) / 2;
        canvas.text(options.xLabel, std::max(layout.metrics.margin, centred), layout.xLabelTop, scale, kInk);
    }
    if (!options.yLabel.empty()) canvas.text(options.yLabel, layout.metrics.margin, layout.yLabelTop, scale, kInk);
}

}  // namespace

// ---------------------------------------------------------------------------
// Public interface.

glm::dvec2 PlotFrame::toPixel(double x, double y) const {
    return {xPixelOfLog(*this, std::log10(x)), yPixelOfLog(*this, std::log10(y))};
}

bool isLogPlottable(double value) { return std::isfinite(value) && value > 0.0; }

std::string decadeLabel(int exponent) {
    if (exponent >= 0 && exponent <= 4) {
        std::string label = "1";
        label.append(static_cast<std::size_t>(exponent), '0');
        return label;
    }
    if (exponent == -1) return "0.1";
    if (exponent == -2) return "0.01";
    return "1e" + std::to_string(exponent);
}

vec3 plotSeriesColour(std::size_t seriesIndex) {
    const std::size_t n = std::size(kPaletteSrgb8);
    const int* srgb = kPaletteSrgb8[seriesIndex % n];
    const vec3 colour = fromSrgb8(srgb[0], srgb[1], srgb[2]);
    // Series 8..15: the same hues, darker (a study plots one line per workload x setting).
    return (seriesIndex / n) % 2 == 1 ? colour * 0.3f : colour;
}

PlotFrame computePlotFrame(const std::vector<PlotSeries>& series, const PlotOptions& options) {
    return computeLayout(series, options).frame;
}

Image renderLogLogPlot(const std::vector<PlotSeries>& series, const PlotOptions& options, PlotReport* report) {
    // Layout, then back to front: grid, axes, curves, legend, labels.
    const Layout layout = computeLayout(series, options);
    Canvas canvas(options.width, options.height, kBackground);
    drawGrid(canvas, layout);
    drawAxes(canvas, layout);
    PlotReport result;
    std::vector<float> occupancy(static_cast<std::size_t>(options.width) * options.height, 0.f);
    drawSeries(canvas, layout, series, result, occupancy);
    if (!series.empty()) result.legendArea = drawLegend(canvas, layout, series, occupancy);
    drawLabels(canvas, layout, options);
    if (report != nullptr) *report = result;
    return canvas.toImage();
}

PlotReport writeLogLogPlot(const std::filesystem::path& png, const std::vector<PlotSeries>& series,
                           const PlotOptions& options) {
    PlotReport report;
    const Image image = renderLogLogPlot(series, options, &report);
    writePng(png, image);
    return report;
}

}  // namespace rtlab
