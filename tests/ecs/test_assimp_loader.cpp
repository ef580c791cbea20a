// PLY and FBX through assimp (docs/scene-format.md, "PLY and FBX"): a
// big-endian binary PLY with vertex colours, header counts checked against
// the file's size before assimp allocates for them, and the cameras of
// assimp-testmodels' FBX files.
#include <gtest/gtest.h>

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/world.hpp>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "../temp_dir.hpp"

using namespace rtlab;
using namespace rtlab::ecs;

namespace {

namespace fs = std::filesystem;

void putBigEndian(std::string& out, float v) {
    std::uint32_t bits;
    std::memcpy(&bits, &v, 4);
    for (int shift = 24; shift >= 0; shift -= 8) out += static_cast<char>((bits >> shift) & 0xff);
}

std::string loadError(const fs::path& path) {
    try {
        World world;
        load::loadScene(world, path.string());
    } catch (const InputError& e) {
        return e.what();
    }
    return "(no error)";
}

}  // namespace

TEST(AssimpLoader, BigEndianBinaryPlyWithVertexColours) {
    const fs::path dir = test::freshTempDir("ply_big_endian");
    fs::create_directories(dir);
    std::string ply =
        "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    const float corners[3][3] = {{0.f, 0.f, 0.f}, {2.f, 0.f, 0.f}, {0.f, 3.f, 0.f}};
    const unsigned char colours[3][3] = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}};
    for (int v = 0; v < 3; ++v) {
        for (float c : corners[v]) putBigEndian(ply, c);
        for (unsigned char c : colours[v]) ply += static_cast<char>(c);
    }
    ply += '\x03';
    for (int i = 0; i < 3; ++i) ply += std::string{'\0', '\0', '\0', static_cast<char>(i)};
    std::ofstream(dir / "tri.ply", std::ios::binary) << ply;
    World world;
    load::loadScene(world, (dir / "tri.ply").string());
    ASSERT_EQ(world.meshes().size(), 1u);
    const Geometry& g = world.meshes()[0].geometries[0];
    ASSERT_EQ(g.triangleCount(), 1u);
    ASSERT_EQ(g.colors.size(), g.positions.size());
    for (std::size_t i = 0; i < g.positions.size(); ++i) {
        // assimp may reorder vertices: match each by its position.
        const vec3 p = g.positions[i];
        const vec4 expected = p.x > 1.f ? vec4(0, 1, 0, 1) : (p.y > 1.f ? vec4(0, 0, 1, 1) : vec4(1, 0, 0, 1));
        EXPECT_EQ(g.colors[i], expected) << i;
    }
    const Aabb b = load::worldBounds(world);
    EXPECT_EQ(b.hi, vec3(2.f, 3.f, 0.f));
}

// A 1 KB PLY whose header declares hundreds of millions of elements is
// refused from its header, in milliseconds, before assimp reserves memory
// (it touched 2.4 GB for 2e8 vertices); honest headers still load.
TEST(AssimpLoader, PlyCountsBeyondTheFileSizeAreRefusedBeforeAllocating) {
    const fs::path dir = test::freshTempDir("ply_counts");
    fs::create_directories(dir);
    const std::string properties = "property float x\nproperty float y\nproperty float z\n";
    const std::string face = "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    std::ofstream(dir / "binary.ply", std::ios::binary)
        << "ply\nformat binary_little_endian 1.0\nelement vertex 200000000\n" + properties + face
        << std::string(900, '\x01');
    std::ofstream(dir / "ascii.ply", std::ios::binary)
        << "ply\nformat ascii 1.0\nelement vertex 4000000000\n" + properties + face << "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    std::ofstream(dir / "faces.ply", std::ios::binary)
        << "ply\nformat ascii 1.0\nelement vertex 3\n" + properties +
               "element face 99999999999\nproperty list uchar int vertex_indices\nend_header\n"
        << "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    std::ofstream(dir / "notanumber.ply", std::ios::binary)
        << "ply\nformat ascii 1.0\nelement vertex -5\n" + properties + face << "0 0 0\n";
    std::ofstream(dir / "honest.ply", std::ios::binary)
        << "ply\nformat ascii 1.0\nelement vertex 3\n" + properties + face << "0 0 0\n1 0 0\n0 1 0\n3 0 1 2";
    const auto started = std::chrono::steady_clock::now();
    EXPECT_NE(loadError(dir / "binary.ply").find("declares 200000000 'vertex' elements"), std::string::npos)
        << loadError(dir / "binary.ply");
    EXPECT_NE(loadError(dir / "ascii.ply").find("declares 4000000000 'vertex' elements"), std::string::npos);
    EXPECT_NE(loadError(dir / "faces.ply").find("declares 99999999999 'face' elements"), std::string::npos);
    EXPECT_NE(loadError(dir / "notanumber.ply").find("has count '-5'"), std::string::npos);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count(), 5.0);
    EXPECT_EQ(loadError(dir / "honest.ply"), "(no error)");
}

// The FBX files of assimp-testmodels that carry cameras: each camera becomes
// an entity under its node and the file's camera is the one rendered; their
// lights are not read (no physical unit), so the default sun lights them.
TEST(AssimpLoader, FbxCamerasAreReadAndTheDefaultSunLightsTheScene) {
    const fs::path models = "/usr/share/assimp/models/FBX";
    ASSERT_TRUE(fs::exists(models)) << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    for (const char* file : {"spider.fbx", "huesitos.fbx", "global_settings.fbx", "animation_with_skeleton.fbx"}) {
        World world;
        load::loadScene(world, (models / file).string());
        int cameras = 0;
        world.each<Camera>([&](Entity e, const Camera& c) {
            ++cameras;
            EXPECT_GT(c.yfov, 0.f) << file;
            EXPECT_LT(c.yfov, 3.1f) << file;
            EXPECT_LT(c.znear, c.zfar) << file;
            EXPECT_EQ(world.get<Name>(e)->value.rfind("camera ", 0), 0u) << file << ": from the file";
        });
        EXPECT_GE(cameras, 1) << file;
        ASSERT_TRUE(world.alive(world.activeCamera())) << file;
        EXPECT_EQ(world.get<Name>(world.activeCamera())->value.rfind("camera ", 0), 0u) << file;
        int lights = 0;
        world.each<Light>([&](Entity e, const Light&) {
            ++lights;
            EXPECT_EQ(world.get<Name>(e)->value, "default light") << file;
        });
        EXPECT_EQ(lights, 1) << file;
    }
    // spider.fbx's camera: 49.13 degrees wide (Blender's 35 mm lens on a 32 mm
    // sensor), 16:9, so 2 atan(tan(24.56 deg) / (16 / 9)) = 28.85 degrees high.
    World spider;
    load::loadScene(spider, (models / "spider.fbx").string());
    EXPECT_NEAR(spider.get<Camera>(spider.activeCamera())->yfov, 0.50360f, 1e-3f);
}

// Damaged copies of real OBJ, PLY and FBX files (assimp-testmodels): each cut
// at 12 lengths and with 24 seeded single-byte changes; every load either
// succeeds or is an InputError (exit 2 in the CLI), never a crash or another
// exception. Also run under ASan + UBSan (make test-asan).
TEST(AssimpLoader, TruncatedAndCorruptedFilesLoadOrAreInputErrors) {
    const fs::path models = "/usr/share/assimp/models";
    ASSERT_TRUE(fs::exists(models / "PLY")) << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    const fs::path dir = test::freshTempDir("damaged_models");
    fs::create_directories(dir);
    std::size_t loads = 0, errors = 0;
    for (const char* file : {"OBJ/box.obj", "OBJ/concave_polygon.obj", "OBJ/cube_usemtl.obj", "PLY/cube.ply",
                             "PLY/cube_binary.ply", "PLY/cube_uv.ply", "PLY/float-color.ply", "FBX/box.fbx",
                             "FBX/boxWithCompressedCTypeArray.FBX", "FBX/cubes_with_names.fbx", "FBX/phong_cube.fbx"}) {
        std::ifstream in(models / file, std::ios::binary);
        const std::string original((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        ASSERT_FALSE(original.empty()) << file;
        const std::string ext = fs::path(file).extension().string();
        std::uint64_t state = 0x9e3779b97f4a7c15ull;
        const auto next = [&] {
            state ^= state << 13, state ^= state >> 7, state ^= state << 17;
            return state;
        };
        for (int variant = 0; variant < 36; ++variant) {
            std::string bytes = original;
            if (variant < 12) {
                bytes.resize(original.size() * std::size_t(variant) / 12);
            } else {
                bytes[next() % bytes.size()] = static_cast<char>(next() & 0xff);
            }
            const fs::path damaged = dir / ("damaged" + std::to_string(variant) + ext);
            std::ofstream(damaged, std::ios::binary | std::ios::trunc) << bytes;
            World world;
            try {
                load::loadScene(world, damaged.string());
                ++loads;
            } catch (const InputError& e) {
                ++errors;
                EXPECT_NE(std::string(e.what()).find(damaged.string()), std::string::npos) << file << ": " << e.what();
            } catch (const std::exception& e) {
                ADD_FAILURE() << file << " variant " << variant << ": not an InputError: " << e.what();
            }
        }
    }
    EXPECT_GT(errors, 11u);  // at least every empty file
    EXPECT_GT(loads, 11u);   // most changes are harmless
}

// Non-finite coordinates in a PLY are an InputError; so is an index out of range.
TEST(AssimpLoader, NonFiniteCoordinatesAndBadIndicesInPlyAreInputErrors) {
    const fs::path dir = test::freshTempDir("ply_bad_values");
    fs::create_directories(dir);
    const std::string header =
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    std::ofstream(dir / "nan.ply", std::ios::binary) << header << "0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n";
    std::ofstream(dir / "index.ply", std::ios::binary) << header << "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n";
    EXPECT_NE(loadError(dir / "nan.ply").find("not a finite number"), std::string::npos) << loadError(dir / "nan.ply");
    const std::string index = loadError(dir / "index.ply");
    EXPECT_NE(index, "(no error)");
    EXPECT_NE(index.find("index.ply"), std::string::npos) << index;
}
