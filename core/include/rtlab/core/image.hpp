#pragma once
// Float images with named channels, and their files: multi-channel OpenEXR
// (beauty + AOVs), PNG previews, and image comparison metrics.
//
// Channel naming follows OpenEXR: the beauty image is "R", "G", "B" (and
// optionally "A"); an AOV layer is "layer.R"/"layer.G"/"layer.B" (or any
// "layer.X" single channel, e.g. "depth.Z").
#include <rtlab/core/math.hpp>

#include <array>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace rtlab {

class Image {
public:
    Image() = default;
    Image(int width, int height);

    int width() const { return width_; }
    int height() const { return height_; }
    std::size_t pixelCount() const { return static_cast<std::size_t>(width_) * height_; }

    // Adds a channel filled with `fill`; throws std::logic_error if it exists.
    float* addChannel(const std::string& name, float fill = 0.f);
    // nullptr when absent.
    float* channel(const std::string& name);
    const float* channel(const std::string& name) const;
    bool hasChannel(const std::string& name) const { return channel(name) != nullptr; }
    // Channel names in insertion order.
    std::vector<std::string> channelNames() const;

    // Adds "layer.R", "layer.G", "layer.B" (plain "R", "G", "B" when layer is
    // empty) from one vec3 per pixel, row-major, top row first.
    void addRgbLayer(const std::string& layer, const std::vector<vec3>& pixels);
    // Reads "layer.R/G/B" (or "R/G/B") back; throws std::out_of_range if absent.
    std::vector<vec3> rgbLayer(const std::string& layer) const;
    // The three channels of an RGB layer as planes, without a copy: adds
    // them filled with `fill` (throws std::logic_error if any exists), or
    // finds them (all three nullptr unless all three exist). The pointers
    // stay valid while the image lives, whatever channels are added later.
    std::array<float*, 3> addRgbPlanes(const std::string& layer, float fill = 0.f);
    std::array<const float*, 3> rgbPlanes(const std::string& layer) const;

private:
    // A plane's floats are left uninitialised by the vector (addChannel
    // fills them in parallel: an image-sized fill on one thread was a
    // millisecond per few channels of every frame).
    template <class T>
    struct UninitialisedAllocator : std::allocator<T> {
        template <class U>
        struct rebind {
            using other = UninitialisedAllocator<U>;
        };
        UninitialisedAllocator() = default;
        template <class U>
        UninitialisedAllocator(const UninitialisedAllocator<U>&) noexcept {}
        template <class U>
        void construct(U* p) noexcept {
            ::new (static_cast<void*>(p)) U;
        }
        template <class U, class... Args>
        void construct(U* p, Args&&... args) {
            ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
        }
    };
    struct Channel {
        std::string name;
        std::vector<float, UninitialisedAllocator<float>> data;
    };
    int width_ = 0;
    int height_ = 0;
    std::vector<Channel> channels_;
};

enum class ExrPixelType { Half, Float };

// Writes every channel of `image` to an OpenEXR file (ZIP compression),
// through writeFileAtomically. Throws InputError naming the file on failure.
// Blocks are compressed on OpenEXR's global thread pool, sized to
// threadCount() (the same bytes for any count).
void writeExr(const std::filesystem::path& path, const Image& image, ExrPixelType type = ExrPixelType::Float);

// Reads every channel of an OpenEXR file. Throws InputError naming the file
// when it is missing, unreadable or not an EXR.
Image readExr(const std::filesystem::path& path);

// 8-bit sRGB PNG preview of the "R","G","B" channels of `layer` ("" = beauty),
// scaled by 2^exposure, clamped, sRGB-encoded. Non-finite values become 0.
void writePng(const std::filesystem::path& path, const Image& image, const std::string& layer = "",
              float exposure = 0.f);

// False colour for a heatmap (e.g. cycles per pixel): 0 -> black, then blue,
// cyan, green, yellow, red, white at `scaleMax` and above; linear RGB, so
// writePng shows the intended colours. Non-finite values map to black.
vec3 falseColour(float value, float scaleMax);
// The q-quantile (0..1) of the finite values (nearest rank; 0 when none):
// a heatmap scale that one outlier cannot flatten. Deterministic.
float quantile(const float* values, std::size_t count, double q);

// Writes `path` by calling write(tmpPath) for a temporary sibling file, then
// renaming it over `path`; the temporary file is removed if write throws. So a
// reader never sees a half-written output.
void writeFileAtomically(const std::filesystem::path& path,
                         const std::function<void(const std::filesystem::path& tmpPath)>& write);
void writeTextFileAtomically(const std::filesystem::path& path, const std::string& text);

// Difference of `test` against `reference` over the channels both share
// (by name). Throws InputError when sizes differ or no channel is shared.
struct ImageDifference {
    double maxAbsDiff = 0.0;
    double rmse = 0.0;
    double psnr = 0.0;    // 10 log10(peak^2 / MSE), peak = max(1, max |reference|); +inf when identical
    double relMse = 0.0;  // mean of (t - r)^2 / (r^2 + 1e-2)
    // Share of the relMSE sum held by the worst 1 % of pixels (at least one;
    // a pixel's term summed over the shared channels): near 1 the error is a
    // few pixels (fireflies, a thin feature blurred away), near 0.01 it is
    // spread like noise. 0 when there is no error.
    double relMseWorstPercentShare = 0.0;
    bool identical = false;  // every shared channel bit-identical and channel sets equal
    std::size_t channelsCompared = 0;
    std::size_t nonFiniteValues = 0;  // NaN/Inf found in either image (excluded from the sums)
    // SSIM (Wang et al. 2004: 11x11 Gaussian window, sigma 1.5, K1 0.01,
    // K2 0.03, L 1) of the beauty's Rec.709 luminance clamped to [0, 1] (a
    // display-referred comparison); NaN when either image lacks R, G, B.
    double ssim = 0.0;
};
// The mean SSIM of two single-channel images (same size), as above.
double ssim(const std::vector<float>& test, const std::vector<float>& reference, int width, int height);
ImageDifference compareImages(const Image& test, const Image& reference);

}  // namespace rtlab
