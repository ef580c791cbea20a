// Image storage, EXR/PNG files, atomic writes and comparison metrics.
#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/parallel.hpp>
#include <rtlab/core/rng.hpp>

#define STB_IMAGE_IMPLEMENTATION
#include <stb_image.h>

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace rtlab;

namespace {

// A fresh, empty directory per test, removed afterwards.
class ImageFiles : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir = fs::temp_directory_path() / ("rtlab_test_image_" + std::to_string(::getpid()) + "_" + info->name());
        fs::remove_all(dir);
        fs::create_directories(dir);
    }
    void TearDown() override { fs::remove_all(dir); }

    std::vector<std::string> filesInDir() const {
        std::vector<std::string> names;
        for (const auto& entry : fs::directory_iterator(dir)) names.push_back(entry.path().filename().string());
        return names;
    }

    fs::path dir;
};

std::vector<unsigned char> readBytes(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeBytes(const fs::path& path, const std::vector<unsigned char>& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

std::string readText(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Deterministic pseudo-random channel contents with awkward values.
Image makeTestImage(int width, int height, const std::vector<std::string>& channels) {
    Image image(width, height);
    std::mt19937 rng(1234);
    std::uniform_real_distribution<float> dist(-3.f, 70000.f);
    for (const std::string& name : channels) {
        float* data = image.addChannel(name);
        for (std::size_t i = 0; i < image.pixelCount(); ++i) data[i] = dist(rng) / 7.f;
    }
    return image;
}

bool bitIdentical(const Image& a, const Image& b, const std::string& channel) {
    return std::memcmp(a.channel(channel), b.channel(channel), a.pixelCount() * sizeof(float)) == 0;
}

// Expects `call` to throw InputError whose message contains every fragment.
template <class Call>
void expectInputError(Call&& call, const std::vector<std::string>& fragments) {
    try {
        call();
        ADD_FAILURE() << "expected rtlab::InputError";
    } catch (const InputError& e) {
        for (const std::string& fragment : fragments)
            EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos)
                << "message '" << e.what() << "' lacks '" << fragment << "'";
    }
}

}  // namespace

// ---------------------------------------------------------------------------
// Image

TEST(Image, ChannelsKeepInsertionOrderAndRejectDuplicates) {
    Image image(3, 2);
    EXPECT_EQ(image.pixelCount(), 6u);
    float* z = image.addChannel("depth.Z", 4.f);
    image.addChannel("A");
    ASSERT_NE(z, nullptr);
    EXPECT_EQ(z[5], 4.f);
    EXPECT_EQ(image.channel("depth.Z"), z);
    EXPECT_EQ(image.channel("missing"), nullptr);
    EXPECT_TRUE(image.hasChannel("A"));
    EXPECT_EQ(image.channelNames(), (std::vector<std::string>{"depth.Z", "A"}));
    EXPECT_THROW(image.addChannel("A"), std::logic_error);
}

TEST(Image, ChannelOfEmptyImageExists) {
    Image image;
    image.addChannel("R");
    EXPECT_TRUE(image.hasChannel("R"));
    EXPECT_FALSE(image.hasChannel("G"));
}

TEST(Image, RgbLayerRoundTrip) {
    Image image(2, 1);
    const std::vector<vec3> pixels = {{1.f, 2.f, 3.f}, {4.f, 5.f, 6.f}};
    image.addRgbLayer("", pixels);
    image.addRgbLayer("albedo", {{0.1f, 0.2f, 0.3f}, {0.4f, 0.5f, 0.6f}});
    EXPECT_EQ(image.channelNames(), (std::vector<std::string>{"R", "G", "B", "albedo.R", "albedo.G", "albedo.B"}));
    EXPECT_EQ(image.channel("G")[1], 5.f);
    EXPECT_EQ(image.channel("albedo.B")[0], 0.3f);
    EXPECT_EQ(image.rgbLayer(""), pixels);
    EXPECT_EQ(image.rgbLayer("albedo")[1], vec3(0.4f, 0.5f, 0.6f));
    EXPECT_THROW(image.rgbLayer("normal"), std::out_of_range);
    EXPECT_THROW(image.addRgbLayer("", pixels), std::logic_error);
    EXPECT_THROW(image.addRgbLayer("short", {{1.f, 1.f, 1.f}}), std::invalid_argument);
}

// ---------------------------------------------------------------------------
// OpenEXR

TEST_F(ImageFiles, ExrFloatRoundTripIsExact) {
    Image image = makeTestImage(7, 5, {"R", "G", "B", "depth.Z"});
    image.channel("R")[0] = 1e-30f;  // denormal in half, exact in float
    image.channel("R")[1] = -0.f;
    const fs::path path = dir / "float.exr";
    writeExr(path, image, ExrPixelType::Float);

    const Image back = readExr(path);
    ASSERT_EQ(back.width(), 7);
    ASSERT_EQ(back.height(), 5);
    for (const std::string& name : image.channelNames()) {
        ASSERT_TRUE(back.hasChannel(name)) << name;
        EXPECT_TRUE(bitIdentical(image, back, name)) << name;
    }
    EXPECT_TRUE(compareImages(back, image).identical);
}

TEST_F(ImageFiles, ExrBytesAndPixelsDoNotDependOnTheThreadCount) {
    // Many ZIP blocks of 16 scanlines, so that two threads compress (and
    // decompress) different blocks of one file.
    const Image image = makeTestImage(97, 301, {"R", "G", "B", "depth.Z", "albedo.R"});
    for (int threads : {1, 2, 3}) {
        const ThreadLimit limit(threads);
        ASSERT_EQ(threadCount(), threads);
        writeExr(dir / ("t" + std::to_string(threads) + ".exr"), image, ExrPixelType::Float);
        const Image back = readExr(dir / "t1.exr");
        for (const std::string& name : image.channelNames()) EXPECT_TRUE(bitIdentical(image, back, name)) << name;
    }
    const std::vector<unsigned char> one = readBytes(dir / "t1.exr");
    EXPECT_GT(one.size(), 1000u);
    EXPECT_EQ(readBytes(dir / "t2.exr"), one);
    EXPECT_EQ(readBytes(dir / "t3.exr"), one);
}

TEST_F(ImageFiles, ExrHalfRoundTripWithinHalfPrecision) {
    Image image(4, 3);
    float* r = image.addChannel("R");
    const float values[12] = {0.1f,    0.5f,   1.f,     3.14159f, -2.71828f, 100.25f,
                              1000.3f, 0.001f, 60000.f, 0.f,      -0.75f,    7.7f};
    std::copy(std::begin(values), std::end(values), r);
    const fs::path path = dir / "half.exr";
    writeExr(path, image, ExrPixelType::Half);

    const Image back = readExr(path);
    ASSERT_TRUE(back.hasChannel("R"));
    for (int i = 0; i < 12; ++i) {
        // Half has an 11-bit significand: relative error <= 2^-11 for normal values.
        EXPECT_NEAR(back.channel("R")[i], values[i], std::abs(values[i]) * 0x1p-11f) << i;
    }
    // Proof it really went through half: 0.1 is not representable.
    EXPECT_NE(back.channel("R")[0], 0.1f);
    EXPECT_EQ(back.channel("R")[1], 0.5f);
}

TEST_F(ImageFiles, ExrHalfIsSmallerThanFloat) {
    const Image image = makeTestImage(32, 32, {"R", "G", "B"});
    writeExr(dir / "half.exr", image, ExrPixelType::Half);
    writeExr(dir / "float.exr", image, ExrPixelType::Float);
    EXPECT_LT(fs::file_size(dir / "half.exr"), fs::file_size(dir / "float.exr"));
}

TEST_F(ImageFiles, ExrPreservesChannelNamesAndOrder) {
    const std::vector<std::string> names = {"R", "G", "B", "A", "albedo.R", "albedo.G", "albedo.B", "depth.Z"};
    const Image image = makeTestImage(3, 3, names);
    writeExr(dir / "aovs.exr", image);
    const Image back = readExr(dir / "aovs.exr");
    EXPECT_EQ(back.channelNames(), names);
    for (const std::string& name : names) EXPECT_TRUE(bitIdentical(image, back, name)) << name;
}

TEST_F(ImageFiles, ExrWriteLeavesNoTemporaryFile) {
    writeExr(dir / "out.exr", makeTestImage(2, 2, {"R"}));
    EXPECT_EQ(filesInDir(), std::vector<std::string>{"out.exr"});
}

TEST_F(ImageFiles, ExrWriteRejectsEmptyImages) {
    expectInputError([&] { writeExr(dir / "nochannels.exr", Image(4, 4)); }, {"nochannels.exr", "channel"});
    Image empty(0, 3);
    empty.addChannel("R");
    expectInputError([&] { writeExr(dir / "empty.exr", empty); }, {"empty.exr", "empty"});
    Image unnamed(1, 1);
    unnamed.addChannel("");
    expectInputError([&] { writeExr(dir / "unnamed.exr", unnamed); }, {"unnamed.exr", "channel"});
    EXPECT_TRUE(filesInDir().empty());
}

TEST_F(ImageFiles, ExrWriteIntoMissingDirectoryFails) {
    const fs::path path = dir / "no_such_dir" / "out.exr";
    expectInputError([&] { writeExr(path, makeTestImage(2, 2, {"R"})); }, {path.string(), "does not exist"});
    EXPECT_FALSE(fs::exists(path.parent_path()));  // nothing was created on the way
}

TEST_F(ImageFiles, ExrReadMissingFileFails) {
    const fs::path path = dir / "missing.exr";
    expectInputError([&] { readExr(path); }, {path.string(), "cannot open"});
    expectInputError([&] { readExr(dir); }, {dir.string(), "cannot open"});
    EXPECT_FALSE(fs::exists(path));
}

TEST_F(ImageFiles, ExrReadGarbageFails) {
    std::mt19937 rng(42);
    std::vector<unsigned char> bytes(4096);
    for (unsigned char& b : bytes) b = static_cast<unsigned char>(rng());
    bytes[0] = 'x';  // certainly not the magic number
    writeBytes(dir / "garbage.exr", bytes);
    expectInputError([&] { readExr(dir / "garbage.exr"); }, {"garbage.exr", "not an OpenEXR file"});

    writeBytes(dir / "empty.exr", {});
    expectInputError([&] { readExr(dir / "empty.exr"); }, {"empty.exr", "not an OpenEXR file"});

    // The right magic number followed by noise must not get further.
    for (unsigned seed = 0; seed < 20; ++seed) {
        rng.seed(seed);
        for (unsigned char& b : bytes) b = static_cast<unsigned char>(rng());
        bytes[0] = 0x76, bytes[1] = 0x2f, bytes[2] = 0x31, bytes[3] = 0x01, bytes[4] = 2;
        writeBytes(dir / "noise.exr", bytes);
        EXPECT_THROW(readExr(dir / "noise.exr"), InputError) << "seed " << seed;
    }
}

// OpenEXR believes the sizes inside a header attribute's value (fuzz_exr: an
// 843-byte file took 13 s of memset); rtlab checks them against the bytes
// that hold them before OpenEXR reads the header.
TEST_F(ImageFiles, ExrHeaderSizesBeyondTheirBytesAreRefused) {
    const fs::path path = dir / "order.exr";
    writeExr(path, makeTestImage(4, 4, {"R", "G", "B"}));  // with its string-vector channel-order attribute
    const std::vector<unsigned char> bytes = readBytes(path);
    const std::string type = "stringvector";
    const auto at = std::search(bytes.begin(), bytes.end(), type.begin(), type.end());
    ASSERT_NE(at, bytes.end());
    // After the type name and its 0: the attribute's size, then the first string's length.
    const std::size_t lengthAt = static_cast<std::size_t>(at - bytes.begin()) + type.size() + 1 + 4;
    std::vector<unsigned char> hugeString = bytes;
    hugeString[lengthAt + 3] = 0x7f;  // the first string: 2^31 - something bytes
    writeBytes(dir / "huge_string.exr", hugeString);
    expectInputError(
        [&] { readExr(dir / "huge_string.exr"); },
        {"huge_string.exr", "header attribute 'rtlabChannelOrder' holds a string longer than the attribute"});
    std::vector<unsigned char> hugeAttribute = bytes;
    hugeAttribute[lengthAt - 1] = 0x7f;  // the attribute's own size
    writeBytes(dir / "huge_attribute.exr", hugeAttribute);
    expectInputError([&] { readExr(dir / "huge_attribute.exr"); },
                     {"huge_attribute.exr", "header attribute 'rtlabChannelOrder' declares", "left in the file"});
    // The file itself reads.
    EXPECT_EQ(readExr(path).channelNames().size(), 3u);
}

TEST_F(ImageFiles, ExrReadTruncatedFails) {
    const fs::path full = dir / "full.exr";
    writeExr(full, makeTestImage(64, 48, {"R", "G", "B"}));
    const std::vector<unsigned char> bytes = readBytes(full);
    ASSERT_GT(bytes.size(), 400u);
    ASSERT_NO_THROW(readExr(full));

    // Cut inside the header, the offset table and the pixel data.
    for (std::size_t length : {std::size_t{4}, std::size_t{20}, std::size_t{100}, std::size_t{300}, bytes.size() / 2,
                               bytes.size() - 100, bytes.size() - 1}) {
        const fs::path cut = dir / "cut.exr";
        writeBytes(cut, std::vector<unsigned char>(bytes.begin(), bytes.begin() + static_cast<long>(length)));
        expectInputError([&] { readExr(cut); }, {"cut.exr"});
    }
}

// ---------------------------------------------------------------------------
// PNG

TEST_F(ImageFiles, PngIsSrgbEncoded) {
    // One row: 0.5 -> 188; 0 -> 0; 1 -> 255; 2 clamps to 255; NaN/Inf/-1 -> 0.
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    Image image(4, 2);
    image.addRgbLayer("", {{0.5f, 0.f, 1.f},
                           {2.f, nan, inf},
                           {-1.f, 0.0031308f, 0.18f},
                           {0.25f, 0.25f, 0.25f},
                           {0.5f, 0.5f, 0.5f},
                           {0.5f, 0.5f, 0.5f},
                           {0.5f, 0.5f, 0.5f},
                           {0.5f, 0.5f, 0.5f}});
    const fs::path path = dir / "preview.png";
    writePng(path, image);

    // PNG signature.
    const std::vector<unsigned char> bytes = readBytes(path);
    ASSERT_GT(bytes.size(), 8u);
    const unsigned char signature[8] = {0x89, 'P', 'N', 'G', 0x0d, 0x0a, 0x1a, 0x0a};
    EXPECT_EQ(std::memcmp(bytes.data(), signature, 8), 0);

    // Decoded values.
    int width = 0, height = 0, components = 0;
    unsigned char* pixels =
        stbi_load_from_memory(bytes.data(), static_cast<int>(bytes.size()), &width, &height, &components, 3);
    ASSERT_NE(pixels, nullptr) << stbi_failure_reason();
    const std::vector<unsigned char> rgb(pixels, pixels + width * height * 3);
    stbi_image_free(pixels);
    EXPECT_EQ(width, 4);
    EXPECT_EQ(height, 2);
    EXPECT_EQ(components, 3);
    EXPECT_EQ(rgb[0], 188);
    EXPECT_EQ(rgb[1], 0);
    EXPECT_EQ(rgb[2], 255);
    EXPECT_EQ(rgb[3], 255);
    EXPECT_EQ(rgb[4], 0);
    EXPECT_EQ(rgb[5], 0);
    EXPECT_EQ(rgb[6], 0);
    EXPECT_EQ(rgb[7], 10);    // 0.0031308 * 12.92 * 255 = 10.3
    EXPECT_EQ(rgb[8], 118);   // 1.055 * 0.18^(1/2.4) - 0.055 = 0.4614
    EXPECT_EQ(rgb[9], 137);   // 0.25 -> 0.5371
    EXPECT_EQ(rgb[23], 188);  // last pixel, bottom row
}

TEST_F(ImageFiles, PngExposureAndLayer) {
    Image image(1, 1);
    image.addRgbLayer("", {{1.f, 1.f, 1.f}});
    image.addRgbLayer("albedo", {{0.25f, 0.125f, 1.f}});
    writePng(dir / "albedo.png", image, "albedo", 1.f);  // x2: 0.5, 0.25, 2

    const std::vector<unsigned char> bytes = readBytes(dir / "albedo.png");
    int width = 0, height = 0, components = 0;
    unsigned char* pixels =
        stbi_load_from_memory(bytes.data(), static_cast<int>(bytes.size()), &width, &height, &components, 3);
    ASSERT_NE(pixels, nullptr);
    EXPECT_EQ(pixels[0], 188);
    EXPECT_EQ(pixels[1], 137);
    EXPECT_EQ(pixels[2], 255);
    stbi_image_free(pixels);
}

TEST_F(ImageFiles, PngOfMissingLayerFails) {
    Image image(2, 2);
    image.addChannel("depth.Z");
    image.addChannel("R");
    image.addChannel("G");
    expectInputError([&] { writePng(dir / "depth.png", image, "depth"); }, {"depth.png", "depth.R"});
    expectInputError([&] { writePng(dir / "beauty.png", image); }, {"beauty.png", "'B'"});
    EXPECT_TRUE(filesInDir().empty());
}

// ---------------------------------------------------------------------------
// Comparison

TEST(CompareImages, IdenticalImages) {
    const Image image = makeTestImage(5, 4, {"R", "G", "B"});
    const ImageDifference diff = compareImages(image, image);
    EXPECT_TRUE(diff.identical);
    EXPECT_EQ(diff.channelsCompared, 3u);
    EXPECT_EQ(diff.maxAbsDiff, 0.0);
    EXPECT_EQ(diff.rmse, 0.0);
    EXPECT_EQ(diff.relMse, 0.0);
    EXPECT_EQ(diff.nonFiniteValues, 0u);
    EXPECT_TRUE(std::isinf(diff.psnr) && diff.psnr > 0);
}

TEST(CompareImages, KnownDifference) {
    // Channel R: test {0.5, 2, 1, 1}, reference {0, 2, 1, 1.5}.
    // Channel G: equal, {3, 3, 3, 3}; so 8 values, peak = 3.
    Image test(2, 2), reference(2, 2);
    const float t[4] = {0.5f, 2.f, 1.f, 1.f};
    const float r[4] = {0.f, 2.f, 1.f, 1.5f};
    std::copy(t, t + 4, test.addChannel("R"));
    std::copy(r, r + 4, reference.addChannel("R"));
    test.addChannel("G", 3.f);
    reference.addChannel("G", 3.f);

    const ImageDifference diff = compareImages(test, reference);
    // Squared errors: 0.25 and 0.25, over 8 values: MSE = 0.0625.
    EXPECT_FALSE(diff.identical);
    EXPECT_EQ(diff.channelsCompared, 2u);
    EXPECT_DOUBLE_EQ(diff.maxAbsDiff, 0.5);
    EXPECT_DOUBLE_EQ(diff.rmse, 0.25);
    EXPECT_DOUBLE_EQ(diff.psnr, 10.0 * std::log10(9.0 / 0.0625));
    // relMse = (0.25 / 0.01 + 0.25 / (2.25 + 0.01)) / 8
    EXPECT_NEAR(diff.relMse, (25.0 + 0.25 / 2.26) / 8.0, 1e-12);
    // The worst 1 % of 4 pixels is one pixel: pixel 0's share of the sum.
    EXPECT_NEAR(diff.relMseWorstPercentShare, 25.0 / (25.0 + 0.25 / 2.26), 1e-12);
    EXPECT_EQ(diff.nonFiniteValues, 0u);
}

TEST(CompareImages, PeakIsAtLeastOne) {
    Image test(1, 2), reference(1, 2);
    test.addChannel("Y", 0.1f);
    reference.addChannel("Y", 0.2f);
    const ImageDifference diff = compareImages(test, reference);
    const double mse = std::pow(static_cast<double>(0.1f) - static_cast<double>(0.2f), 2);
    EXPECT_DOUBLE_EQ(diff.psnr, 10.0 * std::log10(1.0 / mse));
}

TEST(CompareImages, NonFiniteValuesAreCountedAndExcluded) {
    Image test(3, 1), reference(3, 1);
    float* t = test.addChannel("R", 1.f);
    reference.addChannel("R", 1.f);
    t[0] = std::numeric_limits<float>::quiet_NaN();
    t[1] = std::numeric_limits<float>::infinity();
    const ImageDifference diff = compareImages(test, reference);
    EXPECT_EQ(diff.nonFiniteValues, 2u);
    EXPECT_EQ(diff.maxAbsDiff, 0.0);
    EXPECT_EQ(diff.rmse, 0.0);
    EXPECT_FALSE(diff.identical);
}

TEST(CompareImages, OnlySharedChannelsAreCompared) {
    Image test(2, 2), reference(2, 2);
    test.addChannel("R", 1.f);
    test.addChannel("extra", 5.f);
    reference.addChannel("R", 1.f);
    const ImageDifference diff = compareImages(test, reference);
    EXPECT_EQ(diff.channelsCompared, 1u);
    EXPECT_EQ(diff.rmse, 0.0);
    EXPECT_FALSE(diff.identical);  // channel sets differ
    EXPECT_TRUE(compareImages(reference, reference).identical);
}

TEST(CompareImages, NegativeZeroIsNotBitIdentical) {
    Image test(1, 1), reference(1, 1);
    test.addChannel("R", -0.f);
    reference.addChannel("R", 0.f);
    const ImageDifference diff = compareImages(test, reference);
    EXPECT_FALSE(diff.identical);
    EXPECT_EQ(diff.rmse, 0.0);
}

TEST(CompareImages, SizeMismatchOrNoSharedChannelFails) {
    Image small(2, 2), large(3, 2);
    small.addChannel("R");
    large.addChannel("R");
    expectInputError([&] { compareImages(small, large); }, {"2x2", "3x2"});
    Image other(2, 2);
    other.addChannel("G");
    EXPECT_THROW(compareImages(small, other), InputError);
}

// ---------------------------------------------------------------------------
// Atomic writes

TEST_F(ImageFiles, AtomicWriteThatThrowsLeavesNothing) {
    const fs::path target = dir / "out.bin";
    fs::path seenTmp;
    try {
        writeFileAtomically(target, [&](const fs::path& tmp) {
            seenTmp = tmp;
            std::ofstream(tmp) << "half-written";
            throw std::runtime_error("writer failed");
        });
        FAIL() << "the writer's exception must propagate";
    } catch (const std::runtime_error& e) {
        EXPECT_STREQ(e.what(), "writer failed");
    }
    EXPECT_EQ(seenTmp.parent_path(), dir);
    EXPECT_NE(seenTmp, target);
    EXPECT_FALSE(fs::exists(target));
    EXPECT_TRUE(filesInDir().empty());
}

TEST_F(ImageFiles, AtomicWriteThatThrowsKeepsOldTarget) {
    const fs::path target = dir / "out.txt";
    writeTextFileAtomically(target, "old");
    EXPECT_THROW(writeFileAtomically(target,
                                     [](const fs::path& tmp) {
                                         std::ofstream(tmp) << "new";
                                         throw std::runtime_error("writer failed");
                                     }),
                 std::runtime_error);
    EXPECT_EQ(readText(target), "old");
    EXPECT_EQ(filesInDir(), std::vector<std::string>{"out.txt"});
}

TEST_F(ImageFiles, AtomicWriteUsesUniqueTemporaryNames) {
    const fs::path target = dir / "out.txt";
    std::vector<fs::path> tmps;
    for (int i = 0; i < 3; ++i)
        writeFileAtomically(target, [&](const fs::path& tmp) {
            tmps.push_back(tmp);
            std::ofstream(tmp) << i;
        });
    EXPECT_NE(tmps[0], tmps[1]);
    EXPECT_NE(tmps[1], tmps[2]);
    EXPECT_EQ(tmps[0].filename().string().rfind("out.txt.tmp", 0), 0u);
    EXPECT_EQ(readText(target), "2");
}

TEST_F(ImageFiles, TextWriteOverwritesExistingFile) {
    const fs::path target = dir / "stats.json";
    writeTextFileAtomically(target, "a much longer first version\n");
    writeTextFileAtomically(target, "{}\n");
    EXPECT_EQ(readText(target), "{}\n");
    EXPECT_EQ(filesInDir(), std::vector<std::string>{"stats.json"});
}

TEST_F(ImageFiles, TextWriteIntoMissingDirectoryFails) {
    const fs::path target = dir / "absent" / "stats.json";
    expectInputError([&] { writeTextFileAtomically(target, "x"); }, {target.string(), "does not exist"});
    EXPECT_FALSE(fs::exists(target.parent_path()));
}

// SSIM (Wang et al. 2004) literal cases: identical images give exactly 1; a
// structure against its flat mean is near 0; mild noise lands in between,
// and more noise scores lower.
TEST(Ssim, KnownCases) {
    const int w = 32, h = 24;
    std::vector<float> checker(w * h), flat(w * h), noisy(w * h), noisier(w * h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::size_t i = std::size_t(y) * w + x;
            checker[i] = ((x / 2 + y / 2) % 2) ? 0.8f : 0.2f;
            flat[i] = 0.5f;
            const float n = float(rtlab::pcgHash(std::uint32_t(i)) >> 8) / 16777216.f - 0.5f;
            noisy[i] = checker[i] + 0.05f * n;
            noisier[i] = checker[i] + 0.3f * n;
        }
    EXPECT_EQ(rtlab::ssim(checker, checker, w, h), 1.0);
    EXPECT_LT(rtlab::ssim(flat, checker, w, h), 0.05);
    const double mild = rtlab::ssim(noisy, checker, w, h), strong = rtlab::ssim(noisier, checker, w, h);
    EXPECT_GT(mild, 0.9);
    EXPECT_LT(mild, 1.0);
    EXPECT_LT(strong, mild);
    EXPECT_THROW(rtlab::ssim(checker, std::vector<float>(3), w, h), std::invalid_argument);
}

TEST(Ssim, CompareImagesReportsItForRgbImages) {
    rtlab::Image a(8, 8), b(8, 8);
    a.addRgbLayer("", std::vector<rtlab::vec3>(64, rtlab::vec3(0.3f)));
    b.addRgbLayer("", std::vector<rtlab::vec3>(64, rtlab::vec3(0.3f)));
    EXPECT_NEAR(rtlab::compareImages(a, b).ssim, 1.0, 1e-12);
    rtlab::Image c(8, 8), d(8, 8);
    c.addChannel("depth.Z", 1.f);
    d.addChannel("depth.Z", 1.f);
    EXPECT_TRUE(std::isnan(rtlab::compareImages(c, d).ssim));
}
