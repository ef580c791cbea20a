// 8-bit sRGB PNG previews, encoded in memory by stb_image_write and written
// through writeFileAtomically.
#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>

// stb's own code is not -Wextra clean; silence it for this include only.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STBI_WRITE_NO_STDIO
#include <stb_image_write.h>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

namespace rtlab {

namespace {

// Linear value (already exposed) -> 8-bit sRGB code: clamp, exact piecewise OETF, round.
std::uint8_t encodeSrgb8(float linear) {
    if (!std::isfinite(linear)) return 0;
    const double v = std::clamp(static_cast<double>(linear), 0.0, 1.0);
    const double encoded = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
    return static_cast<std::uint8_t>(std::lround(std::clamp(encoded, 0.0, 1.0) * 255.0));
}

// stb_image_write sink appending to a byte vector.
void appendBytes(void* context, void* data, int size) {
    auto* bytes = static_cast<std::vector<unsigned char>*>(context);
    const auto* begin = static_cast<const unsigned char*>(data);
    bytes->insert(bytes->end(), begin, begin + size);
}

}  // namespace

void writePng(const std::filesystem::path& path, const Image& image, const std::string& layer, float exposure) {
    // Find the layer's R, G, B planes.
    const char* components[3] = {"R", "G", "B"};
    const float* planes[3];
    for (int c = 0; c < 3; ++c) {
        const std::string name = layer.empty() ? std::string(components[c]) : layer + "." + components[c];
        planes[c] = image.channel(name);
        if (planes[c] == nullptr)
            throw InputError(path.string(), "image has no channel '" + name + "' for a PNG preview");
    }
    if (image.width() <= 0 || image.height() <= 0)
        throw InputError(path.string(), "cannot write an empty " + std::to_string(image.width()) + "x" +
                                            std::to_string(image.height()) + " PNG image");

    // Expose, clamp and encode every value; non-finite input becomes 0.
    const float scale = std::exp2(exposure);
    const std::size_t pixelCount = image.pixelCount();
    std::vector<unsigned char> rgb(pixelCount * 3);
    for (std::size_t i = 0; i < pixelCount; ++i)
        for (int c = 0; c < 3; ++c) {
            const float value = planes[c][i];
            rgb[i * 3 + c] = std::isfinite(value) ? encodeSrgb8(value * scale) : 0;
        }

    // Encode in memory, then publish atomically.
    std::vector<unsigned char> png;
    if (!stbi_write_png_to_func(appendBytes, &png, image.width(), image.height(), 3, rgb.data(), image.width() * 3))
        throw InputError(path.string(), "PNG encoding failed");
    writeFileAtomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (!out) throw InputError(path.string(), "cannot create file");
        out.write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
        out.close();
        if (out.fail()) throw InputError(path.string(), "write failed");
    });
}

}  // namespace rtlab
