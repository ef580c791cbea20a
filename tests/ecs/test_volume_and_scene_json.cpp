// VolumeGrid (procedural fog, .vdb loading) and the scene .json loader
// (docs/scene-format.md): determinism, bounds, thread safety, and strict
// rejection of malformed input with an InputError that names the file.
//
// OpenVDB is included by exactly one translation unit of the project
// (ecs/src/load/vdb_volume.cpp), so this test cannot write .vdb files itself:
// the small valid and invalid files below are embedded as sparse byte images
// (file size + the non-zero byte runs). They were written with OpenVDB 10.0
// (io::File, COMPRESS_ZIP | COMPRESS_ACTIVE_MASK) from:
//   kValidVdb:    a Vec3f grid "velocity" (one voxel), then a float fog grid
//                 "density": linear transform, voxel size 0.5, translation
//                 (1, 2, 3); voxels (i, j, k) in {0, 1}^3 hold 0.25 * (1 + i + j + k).
//   kNegativeVdb: only "density", with voxel (1, 1, 1) set to -1.
//   kNanVdb:      only "density", with voxel (1, 1, 1) set to NaN.
#include <rtlab/core/error.hpp>
#include <rtlab/core/rng.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/volume_grid.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

namespace {

using namespace rtlab;
using namespace rtlab::ecs;
namespace fs = std::filesystem;

// ---------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------

struct SparseBytes {
    struct Run {
        std::size_t offset;
        const char* hex;
    };
    std::size_t size;
    std::vector<Run> runs;

    std::string bytes() const {
        std::string out(size, '\0');
        for (const Run& r : runs) {
            const std::size_t n = std::strlen(r.hex) / 2;
            for (std::size_t i = 0; i < n; ++i)
                out[r.offset + i] = static_cast<char>(std::stoi(std::string(r.hex + 2 * i, 2), nullptr, 16));
        }
        return out;
    }
};

// The files' bytes, hand-aligned: clang-format leaves them as they are.
// clang-format off
const SparseBytes kValidVdb{19983, {
    {0, "2042445600000000e00000000a000000000000000162343833303531662d383164312d346262612d393939382d3134653638"
           "3662666262336100000000020000000800000076656c6f6369747910000000547265655f76656333735f355f345f33000000"
           "007d00000000000000bc26000000000000112700000000000003000000070000000d00000066696c655f62626f785f6d6178"
           "0500000076656333690c"},
    {175, "0d00000066696c655f62626f785f6d696e0500000076656333690c"},
    {217, "1000000066696c655f636f6d7072657373696f6e06000000737472696e67130000007a6970202b206163746976652076616c"
           "7565731100000066696c655f64656c617965645f6c6f61640d0000005f5f64656c617965646c6f61641500000001"},
    {325, "14000000000000000e00000066696c655f6d656d5f627974657305000000696e74363408000000a041090000000000100000"
           "0066696c655f766f78656c5f636f756e7405000000696e743634080000000100000000000000040000006e616d6506000000"
           "737472696e670800000076656c6f636974790f000000556e69666f726d5363616c654d6170000000000000f03f0000000000"
           "00f03f000000000000f03f000000000000f03f000000000000f03f000000000000f03f000000000000f03f000000000000f0"
           "3f000000000000f03f000000000000f03f000000000000f03f000000000000f03f000000000000e03f000000000000e03f00"
           "0000000000e03f01"},
    {602, "01"},
    {618, "01"},
    {8819, "01"},
    {9852, "01"},
    {9916, "01"},
    {9981, "f4ffffffffffffff0000803f00000040000040400700000064656e7369747910000000547265655f666c6f61745f355f345f"
           "33000000004c27000000000000ae4d0000000000000f4e000000000000020000000800000005000000636c61737306000000"
           "737472696e670a000000666f6720766f6c756d650d00000066696c655f62626f785f6d61780500000076656333690c000000"
           "0100000001000000010000000d00000066696c655f62626f785f6d696e0500000076656333690c"},
    {10185, "1000000066696c655f636f6d7072657373696f6e06000000737472696e670d0000006163746976652076616c756573110000"
           "0066696c655f64656c617965645f6c6f61640d0000005f5f64656c617965646c6f61641500000001"},
    {10287, "1f000000000000000e00000066696c655f6d656d5f627974657305000000696e7436340800000090b1040000000000100000"
           "0066696c655f766f78656c5f636f756e7405000000696e743634080000000800000000000000040000006e616d6506000000"
           "737472696e670700000064656e7369747918000000556e69666f726d5363616c655472616e736c6174654d61700000000000"
           "00f03f00000000000000400000000000000840000000000000e03f000000000000e03f000000000000e03f000000000000e0"
           "3f000000000000e03f000000000000e03f000000000000004000000000000000400000000000000040000000000000104000"
           "000000000010400000000000001040000000000000f03f000000000000f03f000000000000f03f0100000000000000000000"
           "0001"},
    {10604, "01"},
    {18797, "01"},
    {19822, "03030000000000000303"},
    {19886, "03030000000000000303"},
    {19953, "803e0000003f0000003f0000403f0000003f0000403f0000403f0000803f"},
}};
const SparseBytes kNegativeVdb{10047, {
    {0, "2042445600000000e00000000a000000000000000162663264393531642d646330652d343361662d383663642d3831643039"
           "6332353339363000000000010000000700000064656e7369747910000000547265655f666c6f61745f355f345f3300000000"
           "7c00000000000000de260000000000003f27000000000000020000000800000005000000636c61737306000000737472696e"
           "670a000000666f6720766f6c756d650d00000066696c655f62626f785f6d61780500000076656333690c0000000100000001"
           "000000010000000d00000066696c655f62626f785f6d696e0500000076656333690c"},
    {249, "1000000066696c655f636f6d7072657373696f6e06000000737472696e670d0000006163746976652076616c756573110000"
           "0066696c655f64656c617965645f6c6f61640d0000005f5f64656c617965646c6f61641500000001"},
    {351, "20000000000000000e00000066696c655f6d656d5f627974657305000000696e7436340800000090b1040000000000100000"
           "0066696c655f766f78656c5f636f756e7405000000696e743634080000000800000000000000040000006e616d6506000000"
           "737472696e670700000064656e7369747918000000556e69666f726d5363616c655472616e736c6174654d61700000000000"
           "00f03f00000000000000400000000000000840000000000000e03f000000000000e03f000000000000e03f000000000000e0"
           "3f000000000000e03f000000000000e03f000000000000004000000000000000400000000000000040000000000000104000"
           "000000000010400000000000001040000000000000f03f000000000000f03f000000000000f03f0100000000000000000000"
           "0001"},
    {668, "01"},
    {8861, "01"},
    {9886, "03030000000000000303"},
    {9950, "03030000000000000303"},
    {10017, "803e0000003f0000003f0000403f0000003f0000403f0000403f000080bf"},
}};
const SparseBytes kNanVdb{10047, {
    {0, "2042445600000000e00000000a000000000000000137643630363162342d316139302d343838372d396363642d3063663365"
           "3033393763653100000000010000000700000064656e7369747910000000547265655f666c6f61745f355f345f3300000000"
           "7c00000000000000de260000000000003f27000000000000020000000800000005000000636c61737306000000737472696e"
           "670a000000666f6720766f6c756d650d00000066696c655f62626f785f6d61780500000076656333690c0000000100000001"
           "000000010000000d00000066696c655f62626f785f6d696e0500000076656333690c"},
    {249, "1000000066696c655f636f6d7072657373696f6e06000000737472696e670d0000006163746976652076616c756573110000"
           "0066696c655f64656c617965645f6c6f61640d0000005f5f64656c617965646c6f61641500000001"},
    {351, "20000000000000000e00000066696c655f6d656d5f627974657305000000696e7436340800000090b1040000000000100000"
           "0066696c655f766f78656c5f636f756e7405000000696e743634080000000800000000000000040000006e616d6506000000"
           "737472696e670700000064656e7369747918000000556e69666f726d5363616c655472616e736c6174654d61700000000000"
           "00f03f00000000000000400000000000000840000000000000e03f000000000000e03f000000000000e03f000000000000e0"
           "3f000000000000e03f000000000000e03f000000000000004000000000000000400000000000000040000000000000104000"
           "000000000010400000000000001040000000000000f03f000000000000f03f000000000000f03f0100000000000000000000"
           "0001"},
    {668, "01"},
    {8861, "01"},
    {9886, "03030000000000000303"},
    {9950, "03030000000000000303"},
    {10017, "803e0000003f0000003f0000403f0000003f0000403f0000403f0000c07f"},
}};
// clang-format on

// A fresh folder per test (tests run as separate processes, possibly in
// parallel), removed afterwards.
class TempDir {
public:
    TempDir() {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        path_ = fs::temp_directory_path() / ("rtlab_" + std::string(info->test_suite_name()) + "_" + info->name() +
                                             "_" + std::to_string(::getpid()));
        fs::remove_all(path_);
        fs::create_directories(path_);
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path_, ec);
    }
    const fs::path& path() const { return path_; }
    fs::path write(const std::string& name, const std::string& contents) const {
        const fs::path p = path_ / name;
        std::ofstream out(p, std::ios::binary);
        out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
        return p;
    }

private:
    fs::path path_;
};

// Runs fn; returns the InputError message, or "" when nothing was thrown.
std::string inputErrorOf(const std::function<void()>& fn) {
    try {
        fn();
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

bool bitEqual(float a, float b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// Deterministic pseudo-random point in `box`.
vec3 hashedPoint(const Aabb& box, std::uint32_t i) {
    const auto unit = [&](std::uint32_t d) { return static_cast<float>(pcgHash(pcgHash(i) ^ d) >> 8) / 16777216.f; };
    return box.lo + vec3(unit(1), unit(2), unit(3)) * box.extent();
}

const Aabb kFogBox{vec3(-1.f, 0.f, -2.f), vec3(1.f, 1.5f, 0.f)};

// ---------------------------------------------------------------------------
// Procedural fog
// ---------------------------------------------------------------------------

TEST(ProceduralFog, TwoBuildsSampleBitIdenticalValues) {
    const auto a = VolumeGrid::makeProceduralFog(kFogBox, 0.05f, 2.f, 7);
    const auto b = VolumeGrid::makeProceduralFog(kFogBox, 0.05f, 2.f, 7);
    const auto other = VolumeGrid::makeProceduralFog(kFogBox, 0.05f, 2.f, 8);
    EXPECT_EQ(a->activeVoxelCount(), b->activeVoxelCount());
    EXPECT_TRUE(bitEqual(a->maxDensity(), b->maxDensity()));
    Aabb sampled{kFogBox.lo - 0.1f * kFogBox.extent(), kFogBox.hi + 0.1f * kFogBox.extent()};
    std::size_t nonZero = 0, differentSeedDiffers = 0;
    for (std::uint32_t i = 0; i < 1000; ++i) {
        const vec3 p = hashedPoint(sampled, i);
        const float da = a->density(p), db = b->density(p);
        ASSERT_TRUE(bitEqual(da, db)) << "sample " << i << ": " << da << " vs " << db;
        nonZero += da > 0.f;
        differentSeedDiffers += !bitEqual(da, other->density(p));
    }
    EXPECT_GT(nonZero, 100u) << "the blob should fill a good part of the box";
    EXPECT_GT(differentSeedDiffers, 100u) << "the seed should change the noise";
}

TEST(ProceduralFog, ZeroOutsideBoundsAndBoundedByPeak) {
    const float peak = 2.f;
    const auto fog = VolumeGrid::makeProceduralFog(kFogBox, 0.05f, peak, 3);
    EXPECT_EQ(fog->name(), "procedural_fog");
    EXPECT_GT(fog->activeVoxelCount(), 0u);
    EXPECT_GT(fog->maxDensity(), 0.f);
    EXPECT_LE(fog->maxDensity(), peak);
    EXPECT_GT(fog->density(kFogBox.center()), 0.f);

    // The density support lies inside the requested box.
    const Aabb wb = fog->worldBounds();
    ASSERT_FALSE(wb.empty());
    for (int a = 0; a < 3; ++a) {
        EXPECT_GE(wb.lo[a], kFogBox.lo[a] - 1e-4f) << "axis " << a;
        EXPECT_LE(wb.hi[a], kFogBox.hi[a] + 1e-4f) << "axis " << a;
    }
    // Every sample is within [0, maxDensity]; outside the box it is 0.
    const Aabb around{kFogBox.lo - kFogBox.extent(), kFogBox.hi + kFogBox.extent()};
    for (std::uint32_t i = 0; i < 4000; ++i) {
        const vec3 p = hashedPoint(around, i);
        const float d = fog->density(p);
        ASSERT_TRUE(std::isfinite(d));
        ASSERT_GE(d, 0.f);
        ASSERT_LE(d, fog->maxDensity());
        const bool inside =
            glm::all(glm::greaterThanEqual(p, kFogBox.lo)) && glm::all(glm::lessThanEqual(p, kFogBox.hi));
        if (!inside) {
            ASSERT_EQ(d, 0.f) << "outside the box at " << p.x << ", " << p.y << ", " << p.z;
        }
    }
    // Zero next to the faces (the blob fades out before reaching them).
    const vec3 c = kFogBox.center(), h = 0.5f * kFogBox.extent();
    for (int a = 0; a < 3; ++a)
        for (float s : {-1.f, 1.f}) {
            vec3 p = c;
            p[a] += s * 0.97f * h[a];
            EXPECT_EQ(fog->density(p), 0.f) << "near face " << a << (s < 0 ? "-" : "+");
        }
    // NaN and far-away positions are 0, never a crash.
    const float nan = std::numeric_limits<float>::quiet_NaN();
    EXPECT_EQ(fog->density(vec3(nan, 0.f, 0.f)), 0.f);
    EXPECT_EQ(fog->density(vec3(1e30f)), 0.f);
}

TEST(ProceduralFog, ConcurrentSamplingMatchesSerial) {
    const auto fog = VolumeGrid::makeProceduralFog(kFogBox, 0.04f, 1.f, 11);
    constexpr std::uint32_t kSamples = 1u << 14;  // odd strides below visit every index
    std::vector<float> serial(kSamples);
    for (std::uint32_t i = 0; i < kSamples; ++i) serial[i] = fog->density(hashedPoint(kFogBox, i));
    constexpr unsigned kThreads = 4;
    std::vector<std::vector<float>> results(kThreads, std::vector<float>(kSamples));
    std::vector<std::thread> threads;
    for (unsigned t = 0; t < kThreads; ++t)
        threads.emplace_back([&, t] {
            // Each thread walks the samples in a different order.
            for (std::uint32_t n = 0; n < kSamples; ++n) {
                const std::uint32_t i = (n * (2 * t + 1) + 97 * t) & (kSamples - 1);
                results[t][i] = fog->density(hashedPoint(kFogBox, i));
            }
        });
    for (std::thread& th : threads) th.join();
    for (unsigned t = 0; t < kThreads; ++t)
        for (std::uint32_t i = 0; i < kSamples; ++i) ASSERT_TRUE(bitEqual(results[t][i], serial[i])) << t << "/" << i;
}

TEST(ProceduralFog, DegenerateArguments) {
    EXPECT_THROW(VolumeGrid::makeProceduralFog(kFogBox, 0.f, 1.f, 0), std::invalid_argument);
    EXPECT_THROW(VolumeGrid::makeProceduralFog(kFogBox, -0.1f, 1.f, 0), std::invalid_argument);
    EXPECT_THROW(VolumeGrid::makeProceduralFog(Aabb{}, 0.1f, 1.f, 0), std::invalid_argument);
    EXPECT_THROW(VolumeGrid::makeProceduralFog(kFogBox, 0.1f, -1.f, 0), std::invalid_argument);
    EXPECT_THROW(VolumeGrid::makeProceduralFog(Aabb{vec3(0.f), vec3(1000.f)}, 0.001f, 1.f, 0), std::invalid_argument);
    // Zero peak: a valid, empty medium.
    const auto none = VolumeGrid::makeProceduralFog(kFogBox, 0.1f, 0.f, 0);
    EXPECT_EQ(none->activeVoxelCount(), 0u);
    EXPECT_EQ(none->maxDensity(), 0.f);
    EXPECT_TRUE(none->worldBounds().empty());
    EXPECT_EQ(none->density(kFogBox.center()), 0.f);
}

// ---------------------------------------------------------------------------
// .vdb files
// ---------------------------------------------------------------------------

TEST(VdbFile, LoadsTheFirstFloatGridAndSamplesIt) {
    TempDir dir;
    const fs::path file = dir.write("valid.vdb", kValidVdb.bytes());
    for (const std::string gridName : {"", "density"}) {
        const auto g = VolumeGrid::loadVdb(file, gridName);
        EXPECT_EQ(g->name(), "density");
        EXPECT_EQ(g->activeVoxelCount(), 8u);
        EXPECT_FLOAT_EQ(g->maxDensity(), 1.f);
        // Voxel (i, j, k) sits at world (1, 2, 3) + 0.5 * (i, j, k).
        EXPECT_FLOAT_EQ(g->density(vec3(1.f, 2.f, 3.f)), 0.25f);
        EXPECT_FLOAT_EQ(g->density(vec3(1.5f, 2.5f, 3.5f)), 1.f);
        EXPECT_FLOAT_EQ(g->density(vec3(1.25f, 2.f, 3.f)), 0.375f);  // trilinear
        // Bounds: the trilinear support, one voxel beyond the active ones.
        const Aabb b = g->worldBounds();
        EXPECT_NEAR(b.lo.x, 0.5f, 1e-4f);
        EXPECT_NEAR(b.lo.y, 1.5f, 1e-4f);
        EXPECT_NEAR(b.lo.z, 2.5f, 1e-4f);
        EXPECT_NEAR(b.hi.x, 2.f, 1e-4f);
        EXPECT_NEAR(b.hi.y, 3.f, 1e-4f);
        EXPECT_NEAR(b.hi.z, 4.f, 1e-4f);
        EXPECT_EQ(g->density(vec3(0.f)), 0.f);
        EXPECT_EQ(g->density(vec3(2.5f, 2.f, 3.f)), 0.f);
    }
}

TEST(VdbFile, WrongOrMissingGridNamesTheFile) {
    TempDir dir;
    const fs::path file = dir.write("valid.vdb", kValidVdb.bytes());
    std::string msg = inputErrorOf([&] { VolumeGrid::loadVdb(file, "velocity"); });
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("not a float grid"), std::string::npos) << msg;
    msg = inputErrorOf([&] { VolumeGrid::loadVdb(file, "smoke"); });
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("grid 'smoke' not found"), std::string::npos) << msg;
}

TEST(VdbFile, NegativeOrNonFiniteValuesAreRejected) {
    TempDir dir;
    const fs::path negative = dir.write("negative.vdb", kNegativeVdb.bytes());
    const fs::path nan = dir.write("nan.vdb", kNanVdb.bytes());
    std::string msg = inputErrorOf([&] { VolumeGrid::loadVdb(negative); });
    EXPECT_NE(msg.find(negative.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("negative"), std::string::npos) << msg;
    msg = inputErrorOf([&] { VolumeGrid::loadVdb(nan); });
    EXPECT_NE(msg.find(nan.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("non-finite"), std::string::npos) << msg;
}

TEST(VdbFile, MissingGarbageAndTruncatedFilesThrowInputError) {
    TempDir dir;
    const auto expectInputError = [](const fs::path& p, const std::string& what) {
        const std::string msg = inputErrorOf([&] { VolumeGrid::loadVdb(p); });
        EXPECT_NE(msg.find(p.string()), std::string::npos) << what << ": " << (msg.empty() ? "no error" : msg);
        EXPECT_NE(msg.find(what), std::string::npos) << msg;
    };
    expectInputError(dir.path() / "missing.vdb", "cannot open");
    expectInputError(dir.path(), "cannot open");  // a directory
    expectInputError(dir.write("empty.vdb", ""), "not a VDB file");
    expectInputError(dir.write("text.vdb", "this is not a volume, just some text\n"), "not a VDB file");
    // Right magic number, then garbage.
    std::string garbage("\x20\x42\x44\x56\0\0\0\0", 8);
    for (std::uint32_t i = 0; i < 600; ++i) garbage.push_back(static_cast<char>(pcgHash(i)));
    expectInputError(dir.write("garbage.vdb", garbage), "");
    // Right magic number, a file format version from the future.
    std::string future("\x20\x42\x44\x56\0\0\0\0\xff\xff\0\0", 12);
    expectInputError(dir.write("future.vdb", future), "unsupported VDB file format version");

    // Every prefix of a valid file fails cleanly (header, metadata, grid
    // descriptors, topology and compressed leaf data are all cut somewhere).
    const std::string valid = kValidVdb.bytes();
    std::vector<std::size_t> cuts = {1, 7, 8, 9, 12, 16, 40, 57, 61, 65, 100, 124, 125, 200, 400, 600, 1000};
    for (std::size_t n = 1500; n < valid.size(); n += 1499) cuts.push_back(n);
    cuts.push_back(valid.size() - 1);
    for (std::size_t n : cuts) {
        SCOPED_TRACE("truncated to " + std::to_string(n) + " bytes");
        expectInputError(dir.write("truncated.vdb", valid.substr(0, n)), n < 8 ? "not a VDB file" : "truncated");
    }
}

// ---------------------------------------------------------------------------
// Scene .json
// ---------------------------------------------------------------------------

const fs::path kBoxTextured = "/usr/share/assimp/models/glTF2/BoxTextured-glTF/BoxTextured.gltf";

std::size_t countLights(const World& world, LightType type) {
    std::size_t n = 0;
    world.each<Light>([&](Entity, const Light& l) { n += l.type == type; });
    return n;
}

Entity findByName(const World& world, const std::string& name) {
    Entity found = kNullEntity;
    world.each<Name>([&](Entity e, const Name& n) {
        if (n.value == name) found = e;
    });
    return found;
}

vec3 forwardOf(const World& world, Entity e) {
    const LocalTransform* t = world.get<LocalTransform>(e);
    return t ? t->rotation * vec3(0.f, 0.f, -1.f) : vec3(0.f);
}

TEST(SceneJson, GltfFogRectLightAndCameraPath) {
    if (!fs::exists(kBoxTextured))
        GTEST_SKIP() << kBoxTextured.string() << " is missing: scripts/install-deps.sh installs assimp-testmodels";
    World gltfOnly;
    load::loadGltf(gltfOnly, kBoxTextured);

    TempDir dir;
    const fs::path scene = dir.write("scene.json", R"({
      "name": "box in fog",
      "frameSeconds": 0.05,
      "background": [0.1, 0.2, 0.3],
      "gltf": [ { "file": ")" + kBoxTextured.string() + R"(", "translation": [0, 0.5, 0],
                  "rotation": [0, 0.7071068, 0, 0.7071068], "scale": [2, 2, 2] } ],
      "volumes": [ { "procedural": "fog", "bounds": [[-2, 0, -2], [2, 2, 2]], "voxelSize": 0.1,
                     "density": 2.0, "seed": 5, "albedo": [0.9, 0.9, 0.9] } ],
      "lights": [ { "type": "rect", "name": "panel", "color": [1, 0.9, 0.8], "intensity": 12,
                    "size": [1, 0.5], "position": [0, 3, 0], "lookAt": [0, 0, 0] } ],
      "camera": { "position": [0, 1, 6], "lookAt": [0, 0.5, 0], "yfov": 0.7 },
      "cameraPath": [ { "time": 0, "position": [0, 1, 6], "lookAt": [0, 0.5, 0] },
                      { "time": 1, "position": [6, 1, 0], "lookAt": [0, 0.5, 0] },
                      { "time": 2, "position": [0, 1, -6], "lookAt": [0, 0.5, 0] } ]
    })");
    World world;
    load::loadSceneJson(world, scene);

    EXPECT_EQ(world.settings().name, "box in fog");
    EXPECT_FLOAT_EQ(world.settings().frameSeconds, 0.05f);
    EXPECT_FLOAT_EQ(world.settings().backgroundRadiance.z, 0.3f);
    // glTF entities + its parent + volume + light + camera.
    EXPECT_EQ(world.entityCount(), gltfOnly.entityCount() + 4);
    EXPECT_EQ(world.meshes().size(), gltfOnly.meshes().size());
    EXPECT_EQ(world.count<MeshInstance>(), gltfOnly.count<MeshInstance>());
    EXPECT_GE(world.count<MeshInstance>(), 1u);
    const Entity parent = findByName(world, "BoxTextured");
    ASSERT_TRUE(world.alive(parent));
    EXPECT_FLOAT_EQ(world.get<LocalTransform>(parent)->translation.y, 0.5f);
    EXPECT_FLOAT_EQ(world.get<LocalTransform>(parent)->scale.x, 2.f);

    ASSERT_EQ(world.volumeGrids().size(), 1u);
    ASSERT_EQ(world.count<Volume>(), 1u);
    world.each<Volume>([&](Entity, const Volume& v) {
        EXPECT_EQ(v.grid, 0u);
        EXPECT_FLOAT_EQ(v.albedo.x, 0.9f);
    });
    EXPECT_GT(world.volumeGrids()[0]->density(vec3(0.f, 1.f, 0.f)), 0.f);

    ASSERT_EQ(world.count<Light>(), 1u);
    EXPECT_EQ(countLights(world, LightType::Rect), 1u);
    const Entity panel = findByName(world, "panel");
    ASSERT_TRUE(world.alive(panel));
    EXPECT_FLOAT_EQ(world.get<Light>(panel)->intensity, 12.f);
    EXPECT_FLOAT_EQ(world.get<Light>(panel)->size.y, 0.5f);
    const vec3 down = forwardOf(world, panel);  // looking straight down: parallel to +Y up
    EXPECT_NEAR(down.y, -1.f, 1e-5f);
    EXPECT_TRUE(isFinite(world.get<LocalTransform>(panel)->rotation * vec3(1.f)));

    ASSERT_EQ(world.count<Camera>(), 1u);
    const Entity cam = world.activeCamera();
    ASSERT_TRUE(world.alive(cam));
    EXPECT_FLOAT_EQ(world.get<Camera>(cam)->yfov, 0.7f);
    const vec3 f = forwardOf(world, cam);
    const vec3 expected = glm::normalize(vec3(0.f, 0.5f, 0.f) - vec3(0.f, 1.f, 6.f));
    EXPECT_NEAR(glm::dot(f, expected), 1.f, 1e-5f);

    ASSERT_EQ(world.animations().size(), gltfOnly.animations().size() + 1);
    const AnimationClip& path = world.animations().back();
    ASSERT_EQ(path.channels.size(), 2u);
    for (const AnimationChannel& c : path.channels) {
        EXPECT_EQ(c.target, cam);
        EXPECT_EQ(c.interpolation, Interpolation::Linear);
        EXPECT_EQ(c.times.size(), 3u);
        EXPECT_EQ(c.values.size(), 3u * c.componentsPerKey);
    }
    EXPECT_FLOAT_EQ(path.duration(), 2.f);

    // The path drives the camera: half-way to the second key at t = 0.5.
    world.update(0.5f);
    const LocalTransform* t = world.get<LocalTransform>(cam);
    EXPECT_NEAR(t->translation.x, 3.f, 1e-4f);
    EXPECT_NEAR(t->translation.z, 3.f, 1e-4f);
}

TEST(SceneJson, VdbByRelativePathLightsOfEveryKindNoGltf) {
    TempDir dir;
    dir.write("valid.vdb", kValidVdb.bytes());
    const fs::path scene = dir.write("lights.json", R"({
      "volumes": [ { "file": "valid.vdb", "grid": "density", "densityScale": 3, "translation": [1, 0, 0] },
                   { "procedural": "fog", "bounds": [[0, 0, 0], [1, 1, 1]] } ],
      "lights": [ { "type": "point", "position": [0, 2, 0], "intensity": 5, "range": 10 },
                  { "type": "sphere", "position": [1, 2, 0], "radius": 0.25 },
                  { "type": "directional", "direction": [0, -1, 0], "intensity": 3 },
                  { "type": "directional", "direction": [0, 1, 0] },
                  { "type": "spot", "position": [0, 0, 5], "lookAt": [0, 0, 0],
                    "innerConeAngle": 0.2, "outerConeAngle": 0.5 } ],
      "camera": { "position": [0, 0, 3], "lookAt": [0, 0, 0] }
    })");
    World world;
    load::loadSceneJson(world, scene);
    EXPECT_EQ(world.settings().name, "lights");  // defaults to the file stem
    EXPECT_EQ(world.volumeGrids().size(), 2u);
    EXPECT_EQ(world.count<Volume>(), 2u);
    EXPECT_EQ(world.volumeGrids()[0]->name(), "density");
    EXPECT_EQ(world.count<Light>(), 5u);
    EXPECT_EQ(countLights(world, LightType::Point), 1u);
    EXPECT_EQ(countLights(world, LightType::Sphere), 1u);
    EXPECT_EQ(countLights(world, LightType::Directional), 2u);
    EXPECT_EQ(countLights(world, LightType::Spot), 1u);
    EXPECT_EQ(world.count<Camera>(), 1u);
    EXPECT_TRUE(world.animations().empty());
    EXPECT_EQ(world.entityCount(), 2u + 5u + 1u);
    world.each<Light>([&](Entity e, const Light& l) {
        const vec3 f = forwardOf(world, e);
        EXPECT_TRUE(isFinite(f));
        EXPECT_NEAR(glm::length(f), 1.f, 1e-5f);
        if (l.type == LightType::Spot) {
            EXPECT_NEAR(f.z, -1.f, 1e-5f);
        }
    });
    // Straight up and straight down, parallel to the up vector: still exact.
    std::vector<float> verticals;
    world.each<Light>([&](Entity e, const Light& l) {
        if (l.type == LightType::Directional) verticals.push_back(forwardOf(world, e).y);
    });
    ASSERT_EQ(verticals.size(), 2u);
    EXPECT_NEAR(std::min(verticals[0], verticals[1]), -1.f, 1e-5f);
    EXPECT_NEAR(std::max(verticals[0], verticals[1]), 1.f, 1e-5f);
}

TEST(SceneJson, CameraPathAloneCreatesAnAnimatedCamera) {
    TempDir dir;
    const fs::path scene = dir.write("path.json", R"({
      "cameraPath": [ { "time": 0.5, "position": [0, 0, 4], "lookAt": [0, 0, 0] },
                      { "time": 1.5, "position": [0, 4, 0.001], "lookAt": [0, 0, 0] } ]
    })");
    World world;
    load::loadSceneJson(world, scene);
    ASSERT_TRUE(world.alive(world.activeCamera()));
    EXPECT_FLOAT_EQ(world.get<LocalTransform>(world.activeCamera())->translation.z, 4.f);
    ASSERT_EQ(world.animations().size(), 1u);
    EXPECT_FLOAT_EQ(world.animationDuration(), 1.5f);
}

struct BadScene {
    const char* label;
    std::string json;
    std::string expected;  // substring of the message (after the file name)
};

TEST(SceneJson, MalformedFilesThrowInputErrorNamingTheFile) {
    TempDir dir;
    dir.write("garbage.vdb", "not a vdb at all");
    const std::string box = kBoxTextured.string();
    const std::vector<BadScene> cases = {
        {"syntax", R"({"name": "x",})", "invalid JSON at byte"},
        {"empty", "", "invalid JSON at byte"},
        {"not an object", R"([1, 2])", "(root): expected an object, got array"},
        {"unknown top-level key", R"({"nmae": "x"})", "nmae: unknown key"},
        {"unknown nested key", R"({"lights": [{"type": "point", "colour": [1, 1, 1]}]})",
         "lights[0].colour: unknown key"},
        {"key of another light type", R"({"lights": [{"type": "point", "size": [1, 1]}]})",
         "lights[0].size: unknown key"},
        {"unknown camera key", R"({"camera": {"position": [0, 0, 1], "lookAt": [0, 0, 0], "fov": 1}})",
         "camera.fov: unknown key"},
        {"duplicate key", R"({"lights": [{"type": "point", "intensity": 1, "intensity": 2}]})",
         "lights[0].intensity: duplicate key"},
        {"wrong type", R"({"frameSeconds": "fast"})", "frameSeconds: expected a number, got string"},
        {"wrong array length", R"({"background": [1, 1]})", "background: expected an array of 3 numbers"},
        {"boolean for number", R"({"lights": [{"type": "point", "intensity": true}]})",
         "lights[0].intensity: expected a number, got boolean"},
        {"gltf not an array", R"({"gltf": {"file": "a.gltf"}})", "gltf: expected an array, got object"},
        {"negative intensity", R"({"lights": [{"type": "point", "intensity": -1}]})",
         "lights[0].intensity: must be >= 0"},
        {"negative rect size", R"({"lights": [{"type": "rect", "size": [-1, 1]}]})", "lights[0].size[0]: must be > 0"},
        {"sphere without radius", R"({"lights": [{"type": "sphere"}]})", "lights[0].radius: required"},
        {"unknown light type", R"({"lights": [{"type": "laser"}]})", "lights[0].type: unknown light type 'laser'"},
        {"inner cone wider than outer",
         R"({"lights": [{"type": "spot", "innerConeAngle": 0.6, "outerConeAngle": 0.5}]})",
         "lights[0].innerConeAngle: must be <= outerConeAngle"},
        {"zero direction", R"({"lights": [{"type": "directional", "direction": [0, 0, 0]}]})",
         "lights[0].direction: direction must be a non-zero vector"},
        {"number overflow", R"({"frameSeconds": 1e999})", "1e999"},
        {"float overflow", R"({"background": [1e300, 0, 0]})", "background[0]: number out of range"},
        {"zero frame time", R"({"frameSeconds": 0})", "frameSeconds: must be > 0"},
        {"missing glTF", R"({"gltf": [{"file": "nowhere/missing.gltf"}]})", "gltf[0].file: no such file"},
        {"gltf without file", R"({"gltf": [{"translation": [0, 0, 0]}]})", "gltf[0].file: required"},
        {"zero scale", R"({"gltf": [{"file": ")" + box + R"(", "scale": [1, 0, 1]}]})",
         fs::exists(kBoxTextured) ? "gltf[0].scale[1]: must be non-zero" : "gltf[0].file: no such file"},
        {"zero quaternion", R"({"gltf": [{"file": ")" + box + R"(", "rotation": [0, 0, 0, 0]}]})",
         fs::exists(kBoxTextured) ? "gltf[0].rotation: not a rotation" : "gltf[0].file: no such file"},
        {"missing vdb", R"({"volumes": [{"file": "smoke.vdb"}]})", "volumes[0].file: no such file"},
        {"file and procedural", R"({"volumes": [{"file": "garbage.vdb", "procedural": "fog"}]})",
         "volumes[0]: give exactly one of"},
        {"unknown procedural", R"({"volumes": [{"procedural": "smoke", "bounds": [[0, 0, 0], [1, 1, 1]]}]})",
         "volumes[0].procedural: unknown procedural volume 'smoke'"},
        {"inverted bounds", R"({"volumes": [{"procedural": "fog", "bounds": [[0, 0, 0], [1, -1, 1]]}]})",
         "volumes[0].bounds: min must be < max"},
        {"negative voxel size",
         R"({"volumes": [{"procedural": "fog", "bounds": [[0, 0, 0], [1, 1, 1]], "voxelSize": -0.1}]})",
         "volumes[0].voxelSize: must be > 0"},
        {"too many voxels",
         R"({"volumes": [{"procedural": "fog", "bounds": [[0, 0, 0], [100, 100, 100]], "voxelSize": 0.01}]})",
         "volumes[0]: procedural fog: bounds / voxel size need more than"},
        {"negative seed", R"({"volumes": [{"procedural": "fog", "bounds": [[0, 0, 0], [1, 1, 1]], "seed": -3}]})",
         "volumes[0].seed: expected an integer"},
        {"albedo above one",
         R"({"volumes": [{"procedural": "fog", "bounds": [[0, 0, 0], [1, 1, 1]], "albedo": [1, 2, 1]}]})",
         "volumes[0].albedo[1]: must be in [0, 1]"},
        {"camera looking at itself", R"({"camera": {"position": [1, 1, 1], "lookAt": [1, 1, 1]}})",
         "camera.lookAt: lookAt must differ from the position"},
        {"camera without pose", R"({"camera": {"yfov": 0.5}})", "camera: needs 'position' and 'lookAt'"},
        {"camera fov too wide", R"({"camera": {"position": [0, 0, 1], "lookAt": [0, 0, 0], "yfov": 4}})",
         "camera.yfov: must be in (0, pi)"},
        {"path of one key", R"({"cameraPath": [{"time": 0, "position": [0, 0, 1], "lookAt": [0, 0, 0]}]})",
         "cameraPath: needs at least 2 keys"},
        {"path times not increasing",
         R"({"cameraPath": [{"time": 1, "position": [0, 0, 1], "lookAt": [0, 0, 0]},
                            {"time": 1, "position": [0, 0, 2], "lookAt": [0, 0, 0]}]})",
         "cameraPath[1].time: times must be strictly increasing"},
        {"path key without lookAt",
         R"({"cameraPath": [{"time": 0, "position": [0, 0, 1]}, {"time": 1, "position": [0, 0, 2]}]})",
         "cameraPath[0].lookAt: required"},
    };
    for (const BadScene& c : cases) {
        SCOPED_TRACE(c.label);
        const fs::path file = dir.write("bad.json", c.json);
        World world;
        const std::string msg = inputErrorOf([&] { load::loadSceneJson(world, file); });
        ASSERT_FALSE(msg.empty()) << "accepted";
        EXPECT_EQ(msg.rfind(file.string() + ": ", 0), 0u) << msg;
        EXPECT_NE(msg.find(c.expected), std::string::npos) << msg;
    }
}

TEST(SceneJson, ErrorsOfReferencedFilesNameThoseFiles) {
    TempDir dir;
    const fs::path vdb = dir.write("garbage.vdb", "not a vdb at all");
    const fs::path gltf = dir.write("broken.gltf", "{ \"asset\": ");
    World world;
    std::string msg = inputErrorOf(
        [&] { load::loadSceneJson(world, dir.write("a.json", R"({"volumes": [{"file": "garbage.vdb"}]})")); });
    EXPECT_EQ(msg.rfind(vdb.string() + ": ", 0), 0u) << msg;
    // A glTF's error follows the scene file and the entry naming it (the
    // entries share one decode budget: the entry that runs it out is named).
    World world2;
    fs::copy_file(fs::path(RTLAB_SOURCE_DIR) / "fuzz" / "scene_json_model.gltf", dir.path() / "triangle.gltf");
    const fs::path twoEntries =
        dir.write("b.json", R"({"gltf": [{"file": "triangle.gltf"}, {"file": "broken.gltf"}]})");
    msg = inputErrorOf([&] { load::loadSceneJson(world2, twoEntries); });
    EXPECT_EQ(msg.rfind(twoEntries.string() + ": gltf[1]: " + gltf.string() + ": ", 0), 0u) << msg;
    // The scene file itself missing.
    World world3;
    msg = inputErrorOf([&] { load::loadSceneJson(world3, dir.path() / "absent.json"); });
    EXPECT_NE(msg.find("absent.json"), std::string::npos) << msg;
}

}  // namespace
