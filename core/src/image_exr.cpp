// OpenEXR files: every Image channel as one EXR channel (ZIP compression).
// Blocks are compressed and decompressed by OpenEXR's own thread pool, as
// many threads as parallel work may use (threadCount()); a file's bytes do
// not depend on it.
//
// An EXR channel list is sorted by name, so the Image's channel order is kept
// in an extra string-vector header attribute and restored when reading.
#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/ImfStringVectorAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <Imath/half.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <fstream>
#include <istream>
#include <mutex>
#include <set>
#include <string>
#include <vector>

namespace rtlab {

namespace {

// Header attribute holding the channel names in Image order.
constexpr const char* kChannelOrderAttribute = "rtlabChannelOrder";

// First four bytes of every OpenEXR file (20000630, little-endian).
constexpr std::array<unsigned char, 4> kExrMagic = {0x76, 0x2f, 0x31, 0x01};

// Largest image readExr accepts: 2^30 floats (4 GiB), so that a corrupt
// header cannot make us allocate without bound.
constexpr std::int64_t kMaxReadValues = std::int64_t{1} << 30;
// The most a file's pixel data can expand (deflate's limit) and the slack for
// tiny files: readExr refuses windows larger than that against the file size.
constexpr std::int64_t kMaxCompressionRatio = 1032;
constexpr std::int64_t kDecodedBytesSlack = std::int64_t{16} << 20;

// The channel order stored by writeExr when it names exactly the file's
// channels; otherwise the file's own (alphabetical) order.
std::vector<std::string> channelOrder(const Imf::Header& header) {
    std::vector<std::string> fileOrder;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) fileOrder.emplace_back(it.name());

    const auto* stored = header.findTypedAttribute<Imf::StringVectorAttribute>(kChannelOrderAttribute);
    if (stored == nullptr) return fileOrder;
    const std::vector<std::string>& order = stored->value();
    const std::set<std::string> unique(order.begin(), order.end());
    const bool samePermutation =
        order.size() == fileOrder.size() && unique.size() == order.size() &&
        std::all_of(order.begin(), order.end(), [&](const std::string& n) { return header.channels().findChannel(n); });
    return samePermutation ? order : fileOrder;
}

// Walks the header(s) of an EXR file (after the magic number and version:
// attributes of name, type name, 32-bit size and value, each header ending
// with an empty name; a multi-part file's list ending with an empty header)
// and returns the problem, or "" when every size fits. OpenEXR believes the
// sizes inside a value: an 843-byte file whose string vector declared
// gigabyte strings took 13 s of memset, and a preview attribute allocates
// width x height pixels. Those, and every attribute's size, are checked
// against the bytes that hold them.
std::string checkExrHeaders(std::istream& in, std::uint64_t fileSize) {
    std::uint64_t pos = 8;  // magic number + version and flags
    in.clear();
    in.seekg(4);
    std::uint32_t versionAndFlags = 0;
    if (!in.read(reinterpret_cast<char*>(&versionAndFlags), 4)) return "the header ends early";
    const bool multiPart = (versionAndFlags & 0x1000u) != 0;
    const auto readName = [&](std::string& name) {
        name.clear();
        for (char c; in.get(c);) {
            ++pos;
            if (c == '\0') return true;
            if (name.size() >= 255) return false;
            name += c;
        }
        return false;
    };
    const auto readInt = [&](std::int32_t& value) {
        if (!in.read(reinterpret_cast<char*>(&value), 4)) return false;
        pos += 4;
        return true;
    };
    for (;;) {  // the headers
        std::string name, type;
        if (!readName(name)) return "the header ends early or has a name over 255 bytes";
        if (name.empty()) return "";  // the end of a multi-part list (an empty header is OpenEXR's to refuse)
        while (!name.empty()) {       // the attributes
            if (!readName(type)) return "the header ends early in attribute '" + name + "'";
            std::int32_t size = 0;
            if (!readInt(size)) return "the header ends early in attribute '" + name + "'";
            const std::uint64_t left = fileSize - std::min(pos, fileSize);
            if (size < 0 || static_cast<std::uint64_t>(size) > left)
                return "header attribute '" + name + "' declares " + std::to_string(size) + " bytes, more than the " +
                       std::to_string(left) + " left in the file";
            const std::uint64_t end = pos + static_cast<std::uint64_t>(size);
            if (type == "stringvector") {
                while (pos < end) {
                    std::int32_t length = 0;
                    if (end - pos < 4 || !readInt(length) || length < 0 ||
                        static_cast<std::uint64_t>(length) > end - pos)
                        return "header attribute '" + name + "' holds a string longer than the attribute";
                    pos += static_cast<std::uint64_t>(length);
                    in.seekg(static_cast<std::streamoff>(pos));
                }
            } else if (type == "preview") {
                std::uint32_t wh[2] = {0, 0};
                if (size < 8 || !in.read(reinterpret_cast<char*>(wh), 8) ||
                    std::uint64_t{wh[0]} * wh[1] * 4 != static_cast<std::uint64_t>(size) - 8)
                    return "header attribute '" + name + "' declares a preview image its bytes do not hold";
            }
            pos = end;
            in.seekg(static_cast<std::streamoff>(pos));
            if (!in) return "the header ends early";
            if (!readName(name)) return "the header ends early or has a name over 255 bytes";
        }
        if (!multiPart) return "";
    }
}

// OpenEXR's thread count for the next file: threadCount(), the global pool
// resized (under a lock) when that changed.
int exrThreads() {
    static std::mutex resizing;
    const int threads = std::max(threadCount(), 1);
    const std::lock_guard<std::mutex> lock(resizing);
    if (Imf::globalThreadCount() != threads) Imf::setGlobalThreadCount(threads);
    return threads;
}

}  // namespace

void writeExr(const std::filesystem::path& path, const Image& image, ExrPixelType type) {
    // Validate what OpenEXR cannot represent.
    const std::vector<std::string> names = image.channelNames();
    if (names.empty()) throw InputError(path.string(), "cannot write an OpenEXR file without channels");
    if (image.width() <= 0 || image.height() <= 0)
        throw InputError(path.string(), "cannot write an empty " + std::to_string(image.width()) + "x" +
                                            std::to_string(image.height()) + " OpenEXR image");

    // Header: full data window, ZIP, one channel per Image channel.
    const Imf::PixelType pixelType = type == ExrPixelType::Half ? Imf::HALF : Imf::FLOAT;
    Imf::Header header(image.width(), image.height());
    header.compression() = Imf::ZIP_COMPRESSION;
    try {
        for (const std::string& name : names) header.channels().insert(name, Imf::Channel(pixelType));
    } catch (const std::exception& e) {
        throw InputError(path.string(), std::string("invalid OpenEXR channel: ") + e.what());
    }
    header.insert(kChannelOrderAttribute, Imf::StringVectorAttribute(names));

    // Frame buffer: float channels point at the image; half ones at converted copies.
    const std::size_t pixelCount = image.pixelCount();
    const std::size_t rowPixels = static_cast<std::size_t>(image.width());
    std::vector<std::vector<half>> halfPlanes;
    Imf::FrameBuffer frameBuffer;
    for (const std::string& name : names) {
        const float* data = image.channel(name);
        if (type == ExrPixelType::Half) {
            std::vector<half>& plane = halfPlanes.emplace_back(pixelCount);
            std::transform(data, data + pixelCount, plane.begin(), [](float v) { return half(v); });
            frameBuffer.insert(name, Imf::Slice(Imf::HALF, reinterpret_cast<char*>(plane.data()), sizeof(half),
                                                sizeof(half) * rowPixels));
        } else {
            // OutputFile only reads from its slices.
            frameBuffer.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(data)),
                                                sizeof(float), sizeof(float) * rowPixels));
        }
    }

    writeFileAtomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream stream(tmp, std::ios::binary | std::ios::trunc);
        if (!stream) throw InputError(path.string(), "cannot create file");
        try {
            // Scope the OutputFile so its line offset table is written before we check the stream.
            Imf::StdOFStream exrStream(stream, tmp.c_str());
            Imf::OutputFile file(exrStream, header, exrThreads());
            file.setFrameBuffer(frameBuffer);
            file.writePixels(image.height());
        } catch (const InputError&) {
            throw;
        } catch (const std::exception& e) {
            throw InputError(path.string(), std::string("cannot write OpenEXR file: ") + e.what());
        }
        stream.close();
        if (stream.fail()) throw InputError(path.string(), "write failed");
    });
}

Image readExr(const std::filesystem::path& path) {
    // Open it ourselves, so a missing file reads as such.
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec)) throw InputError(path.string(), "cannot open: is a directory");
    std::ifstream stream(path, std::ios::binary);
    if (!stream) throw InputError(path.string(), "cannot open: no such file or not readable");

    // The magic number tells an EXR from anything else.
    std::array<unsigned char, 4> magic{};
    stream.read(reinterpret_cast<char*>(magic.data()), magic.size());
    if (stream.gcount() != static_cast<std::streamsize>(magic.size()) || magic != kExrMagic)
        throw InputError(path.string(), "not an OpenEXR file");
    // Its size bounds the header's sizes and the decoded pixels.
    std::error_code sizeError;
    const std::uint64_t fileSize = std::filesystem::file_size(path, sizeError);
    const bool sizeKnown = !sizeError;
    if (sizeKnown) {
        const std::string problem = checkExrHeaders(stream, fileSize);
        if (!problem.empty()) throw InputError(path.string(), "corrupt OpenEXR file: " + problem);
    }
    stream.clear();
    stream.seekg(0);

    try {
        Imf::StdIFStream exrStream(stream, path.c_str());
        Imf::InputFile file(exrStream, exrThreads());
        const Imf::Header& header = file.header();

        // Size of the data window, bounded before allocating anything.
        const Imath::Box2i dataWindow = header.dataWindow();
        const std::int64_t width = std::int64_t{dataWindow.max.x} - dataWindow.min.x + 1;
        const std::int64_t height = std::int64_t{dataWindow.max.y} - dataWindow.min.y + 1;
        if (width <= 0 || height <= 0) throw InputError(path.string(), "OpenEXR file has an empty data window");
        const std::vector<std::string> names = channelOrder(header);
        if (names.empty()) throw InputError(path.string(), "OpenEXR file has no channels");
        if (width > kMaxReadValues || height > kMaxReadValues ||
            width * height > kMaxReadValues / static_cast<std::int64_t>(names.size()))
            throw InputError(path.string(), "OpenEXR image is too large (" + std::to_string(width) + "x" +
                                                std::to_string(height) + ", " + std::to_string(names.size()) +
                                                " channels)");
        // A file's pixels cannot decode to more than deflate's largest ratio
        // (1032:1, ZIP and PIZ) times its size, plus a little: a small file
        // declaring a huge window is corrupt, refused before allocating.
        const std::int64_t fileBytes = static_cast<std::int64_t>(fileSize);
        const std::int64_t decodedBytes = width * height * static_cast<std::int64_t>(names.size()) * 2;  // half
        if (sizeKnown && decodedBytes > kMaxCompressionRatio * fileBytes + kDecodedBytesSlack)
            throw InputError(path.string(), "OpenEXR header declares " + std::to_string(width) + "x" +
                                                std::to_string(height) + " pixels of " + std::to_string(names.size()) +
                                                " channels, more than its " + std::to_string(fileBytes) +
                                                " bytes can hold (corrupt)");
        if (!file.isComplete()) throw InputError(path.string(), "OpenEXR file is truncated or incomplete");

        // One float slice per channel, addressed by data-window coordinates.
        Image image(static_cast<int>(width), static_cast<int>(height));
        Imf::FrameBuffer frameBuffer;
        for (const std::string& name : names) {
            const Imf::Channel* channel = header.channels().findChannel(name);
            if (channel->xSampling != 1 || channel->ySampling != 1)
                throw InputError(path.string(), "subsampled channel '" + name + "' is not supported");
            float* data = image.addChannel(name);
            frameBuffer.insert(name, Imf::Slice::Make(Imf::FLOAT, data, dataWindow, sizeof(float),
                                                      sizeof(float) * static_cast<std::size_t>(width)));
        }
        file.setFrameBuffer(frameBuffer);
        file.readPixels(dataWindow.min.y, dataWindow.max.y);
        return image;
    } catch (const InputError&) {
        throw;
    } catch (const std::exception& e) {
        throw InputError(path.string(), std::string("corrupt or unreadable OpenEXR file: ") + e.what());
    } catch (...) {
        throw InputError(path.string(), "corrupt or unreadable OpenEXR file");
    }
}

}  // namespace rtlab
