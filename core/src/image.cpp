// Image storage, atomic file writes and image comparison metrics.
#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <system_error>

namespace rtlab {

namespace {

// "layer.X", or plain "X" for the beauty layer.
std::string layerChannelName(const std::string& layer, const char* component) {
    return layer.empty() ? std::string(component) : layer + "." + component;
}

// A sibling of `path` that no other writer (thread or process) uses at the same time.
std::filesystem::path uniqueTemporarySibling(const std::filesystem::path& path) {
    static std::atomic<std::uint64_t> counter{0};
    const std::uint64_t serial = counter.fetch_add(1, std::memory_order_relaxed);
    std::filesystem::path tmp = path;
    tmp += ".tmp" + std::to_string(static_cast<long long>(::getpid())) + "." + std::to_string(serial);
    return tmp;
}

}  // namespace

// ---------------------------------------------------------------------------
// Image

Image::Image(int width, int height) : width_(width), height_(height) {
    if (width < 0 || height < 0)
        throw std::invalid_argument("Image: negative size " + std::to_string(width) + "x" + std::to_string(height));
}

float* Image::addChannel(const std::string& name, float fill) {
    if (channel(name) != nullptr) throw std::logic_error("Image: channel '" + name + "' already exists");
    // At least one element, so that channel() is never null for an existing
    // channel of an empty image; only the first pixelCount() values are pixels.
    const std::size_t count = std::max<std::size_t>(pixelCount(), 1);
    channels_.push_back(Channel{name, {}});
    auto& data = channels_.back().data;
    data.resize(count);  // uninitialised
    parallelForChunks(count, kPixelChunk, [&](std::size_t begin, std::size_t end) {
        std::fill(data.begin() + static_cast<std::ptrdiff_t>(begin), data.begin() + static_cast<std::ptrdiff_t>(end),
                  fill);
    });
    return data.data();
}

float* Image::channel(const std::string& name) {
    return const_cast<float*>(static_cast<const Image&>(*this).channel(name));
}

const float* Image::channel(const std::string& name) const {
    for (const Channel& c : channels_)
        if (c.name == name) return c.data.data();
    return nullptr;
}

std::vector<std::string> Image::channelNames() const {
    std::vector<std::string> names;
    names.reserve(channels_.size());
    for (const Channel& c : channels_) names.push_back(c.name);
    return names;
}

std::array<float*, 3> Image::addRgbPlanes(const std::string& layer, float fill) {
    const std::string names[3] = {layerChannelName(layer, "R"), layerChannelName(layer, "G"),
                                  layerChannelName(layer, "B")};
    // Check all three first so a clash leaves the image unchanged.
    for (const std::string& name : names)
        if (hasChannel(name)) throw std::logic_error("Image: channel '" + name + "' already exists");
    // A channel's data moves with the Channel when channels_ grows: the buffer, not the floats.
    return {addChannel(names[0], fill), addChannel(names[1], fill), addChannel(names[2], fill)};
}

std::array<const float*, 3> Image::rgbPlanes(const std::string& layer) const {
    std::array<const float*, 3> planes = {channel(layerChannelName(layer, "R")), channel(layerChannelName(layer, "G")),
                                          channel(layerChannelName(layer, "B"))};
    if (!planes[0] || !planes[1] || !planes[2]) planes = {nullptr, nullptr, nullptr};
    return planes;
}

void Image::addRgbLayer(const std::string& layer, const std::vector<vec3>& pixels) {
    if (pixels.size() != pixelCount())
        throw std::invalid_argument("Image: layer '" + layer + "' has " + std::to_string(pixels.size()) +
                                    " pixels, image has " + std::to_string(pixelCount()));
    const std::array<float*, 3> out = addRgbPlanes(layer);
    parallelForChunks(pixels.size(), kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
            out[0][i] = pixels[i].x;
            out[1][i] = pixels[i].y;
            out[2][i] = pixels[i].z;
        }
    });
}

std::vector<vec3> Image::rgbLayer(const std::string& layer) const {
    const char* components[3] = {"R", "G", "B"};
    for (const char* component : components) {
        const std::string name = layerChannelName(layer, component);
        if (!hasChannel(name)) throw std::out_of_range("Image: no channel '" + name + "'");
    }
    const std::array<const float*, 3> planes = rgbPlanes(layer);
    std::vector<vec3> pixels(pixelCount());
    parallelForChunks(pixels.size(), kPixelChunk, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) pixels[i] = vec3(planes[0][i], planes[1][i], planes[2][i]);
    });
    return pixels;
}

// ---------------------------------------------------------------------------
// Atomic writes

void writeFileAtomically(const std::filesystem::path& path,
                         const std::function<void(const std::filesystem::path& tmpPath)>& write) {
    // The directory must already exist: creating it is the caller's decision.
    const std::filesystem::path directory = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
    std::error_code ec;
    if (!std::filesystem::is_directory(directory, ec))
        throw InputError(path.string(), "directory '" + directory.string() + "' does not exist");

    // Write the temporary sibling; on any failure leave nothing behind.
    const std::filesystem::path tmp = uniqueTemporarySibling(path);
    try {
        write(tmp);
    } catch (...) {
        std::filesystem::remove(tmp, ec);
        throw;
    }

    // Publish it in one step.
    std::filesystem::rename(tmp, path, ec);
    if (ec) {
        std::error_code ignored;
        std::filesystem::remove(tmp, ignored);
        throw InputError(path.string(), "cannot write: " + ec.message());
    }
}

void writeTextFileAtomically(const std::filesystem::path& path, const std::string& text) {
    writeFileAtomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (!out) throw InputError(path.string(), "cannot create file");
        out.write(text.data(), static_cast<std::streamsize>(text.size()));
        out.close();
        if (out.fail()) throw InputError(path.string(), "write failed");
    });
}

// ---------------------------------------------------------------------------
// Comparison

ImageDifference compareImages(const Image& test, const Image& reference) {
    if (test.width() != reference.width() || test.height() != reference.height())
        throw InputError("image sizes differ: " + std::to_string(test.width()) + "x" + std::to_string(test.height()) +
                         " vs reference " + std::to_string(reference.width()) + "x" +
                         std::to_string(reference.height()));

    // Shared channels, in the test image's order.
    const std::vector<std::string> testNames = test.channelNames();
    const std::vector<std::string> referenceNames = reference.channelNames();
    std::vector<std::string> shared;
    for (const std::string& name : testNames)
        if (reference.hasChannel(name)) shared.push_back(name);
    if (shared.empty()) throw InputError("images share no channel");

    ImageDifference diff;
    diff.channelsCompared = shared.size();
    diff.identical = testNames.size() == referenceNames.size() && shared.size() == testNames.size();

    const std::size_t n = test.pixelCount();
    double peak = 1.0;
    double sumSquared = 0.0;
    double sumRelative = 0.0;
    std::size_t finitePairs = 0;
    std::vector<double> pixelRelative(n, 0.0);  // per pixel, over the shared channels
    for (const std::string& name : shared) {
        const float* t = test.channel(name);
        const float* r = reference.channel(name);
        if (diff.identical && n > 0 && std::memcmp(t, r, n * sizeof(float)) != 0) diff.identical = false;
        for (std::size_t i = 0; i < n; ++i) {
            // Non-finite values are counted, never summed.
            const bool testFinite = std::isfinite(t[i]);
            const bool referenceFinite = std::isfinite(r[i]);
            if (referenceFinite) peak = std::max(peak, std::abs(static_cast<double>(r[i])));
            if (!testFinite || !referenceFinite) {
                diff.nonFiniteValues += (testFinite ? 0 : 1) + (referenceFinite ? 0 : 1);
                continue;
            }
            const double ref = r[i];
            const double delta = static_cast<double>(t[i]) - ref;
            const double squared = delta * delta;
            diff.maxAbsDiff = std::max(diff.maxAbsDiff, std::abs(delta));
            sumSquared += squared;
            const double relative = squared / (ref * ref + 1e-2);
            sumRelative += relative;
            pixelRelative[i] += relative;
            ++finitePairs;
        }
    }

    // Means over the finite pairs; PSNR against the reference's peak.
    const double mse = finitePairs > 0 ? sumSquared / static_cast<double>(finitePairs) : 0.0;
    diff.rmse = std::sqrt(mse);
    diff.relMse = finitePairs > 0 ? sumRelative / static_cast<double>(finitePairs) : 0.0;
    diff.psnr = mse == 0.0 ? std::numeric_limits<double>::infinity() : 10.0 * std::log10(peak * peak / mse);
    // The worst 1 % of pixels' share of the relative error.
    if (sumRelative > 0.0 && n > 0) {
        const std::size_t worst = std::max<std::size_t>(1, n / 100);
        std::nth_element(pixelRelative.begin(), pixelRelative.begin() + static_cast<std::ptrdiff_t>(worst - 1),
                         pixelRelative.end(), std::greater<>());
        double top = 0.0;
        for (std::size_t k = 0; k < worst; ++k) top += pixelRelative[k];
        diff.relMseWorstPercentShare = std::min(1.0, top / sumRelative);  // rounding may put top a hair above
    }

    // SSIM of the display-referred luminance.
    diff.ssim = std::numeric_limits<double>::quiet_NaN();
    const char* rgb[3] = {"R", "G", "B"};
    bool haveRgb = true;
    for (const char* c : rgb) haveRgb = haveRgb && test.hasChannel(c) && reference.hasChannel(c);
    if (haveRgb && n > 0) {
        const auto luminance = [&](const Image& img) {
            std::vector<float> y(n);
            const float *r = img.channel("R"), *g = img.channel("G"), *b = img.channel("B");
            for (std::size_t i = 0; i < n; ++i) {
                const float v = 0.2126f * r[i] + 0.7152f * g[i] + 0.0722f * b[i];
                y[i] = std::isfinite(v) ? std::clamp(v, 0.f, 1.f) : 0.f;
            }
            return y;
        };
        diff.ssim = ssim(luminance(test), luminance(reference), test.width(), test.height());
    }
    return diff;
}

double ssim(const std::vector<float>& x, const std::vector<float>& y, int width, int height) {
    const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    if (n == 0 || x.size() != n || y.size() != n) throw std::invalid_argument("ssim: image sizes do not match");
    // Step: the 11-tap Gaussian (sigma 1.5), renormalised where the window leaves the image.
    constexpr int kRadius = 5;
    double kernel[2 * kRadius + 1];
    for (int k = -kRadius; k <= kRadius; ++k) kernel[k + kRadius] = std::exp(-0.5 * (k * k) / (1.5 * 1.5));
    const auto blur = [&](const std::vector<double>& in) {
        std::vector<double> tmp(n), out(n);
        for (int row = 0; row < height; ++row)
            for (int col = 0; col < width; ++col) {
                double s = 0.0, w = 0.0;
                for (int k = -kRadius; k <= kRadius; ++k) {
                    const int c = col + k;
                    if (c < 0 || c >= width) continue;
                    s += kernel[k + kRadius] * in[std::size_t(row) * width + c];
                    w += kernel[k + kRadius];
                }
                tmp[std::size_t(row) * width + col] = s / w;
            }
        for (int row = 0; row < height; ++row)
            for (int col = 0; col < width; ++col) {
                double s = 0.0, w = 0.0;
                for (int k = -kRadius; k <= kRadius; ++k) {
                    const int r = row + k;
                    if (r < 0 || r >= height) continue;
                    s += kernel[k + kRadius] * tmp[std::size_t(r) * width + col];
                    w += kernel[k + kRadius];
                }
                out[std::size_t(row) * width + col] = s / w;
            }
        return out;
    };
    std::vector<double> xd(n), yd(n), xx(n), yy(n), xy(n);
    for (std::size_t i = 0; i < n; ++i) {
        xd[i] = x[i];
        yd[i] = y[i];
        xx[i] = xd[i] * xd[i];
        yy[i] = yd[i] * yd[i];
        xy[i] = xd[i] * yd[i];
    }
    const std::vector<double> mx = blur(xd), my = blur(yd), sxx = blur(xx), syy = blur(yy), sxy = blur(xy);
    // Step: the SSIM map and its mean.
    constexpr double c1 = (0.01 * 1.0) * (0.01 * 1.0), c2 = (0.03 * 1.0) * (0.03 * 1.0);
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const double vx = std::max(0.0, sxx[i] - mx[i] * mx[i]), vy = std::max(0.0, syy[i] - my[i] * my[i]);
        const double cov = sxy[i] - mx[i] * my[i];
        sum +=
            ((2.0 * mx[i] * my[i] + c1) * (2.0 * cov + c2)) / ((mx[i] * mx[i] + my[i] * my[i] + c1) * (vx + vy + c2));
    }
    return sum / double(n);
}

}  // namespace rtlab
