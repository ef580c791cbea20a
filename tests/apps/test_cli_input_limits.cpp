// Resource limits on hostile input (docs/reliability.md, "Limits"): small
// files that ask for endless reads, gigabytes or hours are refused through
// the command line with exit 2 and one line, before anything big is
// allocated; each case is a literal file written here.
#include "cli_test_util.hpp"

#include <rtlab/study/ray_trace_file.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace rtlab::test {
namespace {

void writeText(const fs::path& path, const std::string& text) { std::ofstream(path, std::ios::binary) << text; }

// Exit 2, one line, containing `expected`.
::testing::AssertionResult refused(const CliRun& r, const std::string& expected) {
    if (r.exitCode != 2) return ::testing::AssertionFailure() << "exit " << r.exitCode << ", not 2:\n" << r.out;
    if (std::count(r.out.begin(), r.out.end(), '\n') != 1)
        return ::testing::AssertionFailure() << "not one line:\n" << r.out;
    if (r.out.find(expected) == std::string::npos)
        return ::testing::AssertionFailure() << "no \"" << expected << "\" in:\n" << r.out;
    return ::testing::AssertionSuccess();
}

// A PNG's signature and IHDR chunk only: stb_image's info reads no further.
std::string pngHeader(std::uint32_t width, std::uint32_t height) {
    std::string s = "\x89PNG\r\n\x1a\n";
    const auto be32 = [&](std::uint32_t v) {
        for (int shift = 24; shift >= 0; shift -= 8) s += char((v >> shift) & 0xff);
    };
    be32(13);
    s += "IHDR";
    be32(width);
    be32(height);
    s += std::string("\x08\x06\x00\x00\x00", 5);  // 8-bit RGBA
    be32(0);                                      // CRC (stb_image does not check it)
    return s;
}

const std::string kQuadObj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n";

TEST(CliInputLimits, DevicesAndPipesAreNeverRead) {
    const fs::path dir = freshDir("limits_devices");
    fs::create_directories(dir);
    fs::create_symlink("/dev/zero", dir / "zero.json");
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "zero.json").string()), "not a regular file"));
    fs::create_symlink("/dev/zero", dir / "zero.mtl");
    writeText(dir / "mtllib.obj", "mtllib zero.mtl\n" + kQuadObj + "f 1 2 3\n");
    EXPECT_TRUE(
        refused(runCli("info --scene " + (dir / "mtllib.obj").string()), "mtllib 'zero.mtl' is not a regular file"));
    // A texture that is a device is a missing texture: a warning, the scene loads.
    fs::create_symlink("/dev/zero", dir / "zero.png");
    writeText(dir / "textured.mtl", "newmtl m\nmap_Kd zero.png\n");
    writeText(dir / "textured.obj", "mtllib textured.mtl\n" + kQuadObj + "usemtl m\nf 1/1 2/2 3/3\n");
    const CliRun textured = runCli("info --scene " + (dir / "textured.obj").string());
    EXPECT_EQ(textured.exitCode, 0) << textured.out;
    EXPECT_NE(textured.out.find("textures: 0"), std::string::npos) << textured.out;
    // A glTF buffer naming a device.
    writeText(dir / "zero_buffer.gltf",
              R"({"asset": {"version": "2.0"}, "buffers": [{"uri": "zero.png", "byteLength": 64}]})");
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "zero_buffer.gltf").string()), "zero_buffer.gltf"));
}

TEST(CliInputLimits, ImagesDeclaringTooManyPixelsAreRefusedBeforeDecoding) {
    const fs::path dir = freshDir("limits_png");
    fs::create_directories(dir);
    writeText(dir / "huge.png", pngHeader(10000, 10000));  // 1e8 pixels: 400 MB as RGBA8, from 33 bytes
    writeText(dir / "huge.mtl", "newmtl m\nmap_Kd huge.png\n");
    writeText(dir / "huge.obj", "mtllib huge.mtl\n" + kQuadObj + "usemtl m\nf 1/1 2/2 3/3\n");
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "huge.obj").string()),
                        "huge.png: image of 10000 x 10000 pixels, more than the 67108864 a texture may have"));
    // Five 8192 x 8192 images, each within the limit: a scene decodes 2^28 pixels plus 16 per compressed byte.
    std::string mtl, shared;
    for (int k = 0; k < 5; ++k) {
        const std::string png = "big" + std::to_string(k) + ".png";
        writeText(dir / png, pngHeader(8192, 8192));
        mtl += "newmtl m" + std::to_string(k) + "\nmap_Kd " + png + "\n";
        shared += "newmtl m" + std::to_string(k) + "\nmap_Kd big0.png\n";
    }
    writeText(dir / "many.mtl", mtl);
    writeText(dir / "many.obj", "mtllib many.mtl\n" + kQuadObj + "usemtl m0\nf 1/1 2/2 3/3\n");
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "many.obj").string()),
                        "many.obj: big4.png: the scene's images have 335544320 pixels, more than the 268438096 it "
                        "may decode (2^28 + 16 per byte of its compressed images"));
    // Four of them are within it, and five materials naming one image read it once: both load
    // (the header-only image is left out with a warning).
    writeText(dir / "four.mtl", mtl.substr(0, mtl.find("newmtl m4")));
    writeText(dir / "four.obj", "mtllib four.mtl\n" + kQuadObj + "usemtl m0\nf 1/1 2/2 3/3\n");
    const CliRun four = runCli("info --scene " + (dir / "four.obj").string());
    EXPECT_EQ(four.exitCode, 0) << four.out;
    writeText(dir / "shared.mtl", shared);
    writeText(dir / "shared.obj", "mtllib shared.mtl\n" + kQuadObj + "usemtl m0\nf 1/1 2/2 3/3\n");
    const CliRun sharedRun = runCli("info --scene " + (dir / "shared.obj").string());
    EXPECT_EQ(sharedRun.exitCode, 0) << sharedRun.out;
    const auto missing = [](const std::string& out) {
        std::size_t n = 0;
        for (std::size_t at = out.find("not found or not readable"); at != std::string::npos;
             at = out.find("not found or not readable", at + 1))
            ++n;
        return n;
    };
    EXPECT_EQ(missing(four.out), 4u) << four.out;
    EXPECT_EQ(missing(sharedRun.out), 1u) << "read once:\n" << sharedRun.out;
}

TEST(CliInputLimits, GltfGeometryDeclaredBeyondItsBuffersIsRefusedBeforeDecoding) {
    const fs::path dir = freshDir("limits_gltf_geometry");
    fs::create_directories(dir);
    // One accessor of 2^24 positions without a bufferView (zeros, allowed: 201 MB decoded), read by 100 primitives.
    const std::string accessor = R"("accessors": [{"count": 16777216, "type": "VEC3", "componentType": 5126}])";
    std::string primitives;
    for (int k = 0; k < 100; ++k) primitives += std::string(k ? ", " : "") + R"({"attributes": {"POSITION": 0}})";
    writeText(dir / "reused.gltf", R"({"asset": {"version": "2.0"}, )" + accessor + R"(, "meshes": [{"primitives": [)" +
                                       primitives + R"(]}], "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]})");
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "reused.gltf").string()),
                        "declare more than 1073741824 bytes of geometry, the most it may decode (1 GiB + 64 x its "
                        "glTF buffers' bytes)"));
    // One morphed mesh (402 MB) instanced by two nodes, each of which owns a copy with its rest pose.
    writeText(dir / "morphed.gltf",
              R"({"asset": {"version": "2.0"}, )" + accessor +
                  R"(, "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "targets": [{"POSITION": 0}]}]}],)"
                  R"( "nodes": [{"mesh": 0}, {"mesh": 0}], "scenes": [{"nodes": [0, 1]}]})");
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "morphed.gltf").string()),
                        "bytes of geometry, the most it may decode"));
    // (A scene .json's entries share one budget: GltfLoaderAssimpModels.ADecodeBudgetIsSharedByTheFilesOfOneLoad.)
}

TEST(CliInputLimits, DeepJsonAndHugeStudiesAndConfigurationsAreRefused) {
    const fs::path dir = freshDir("limits_json");
    fs::create_directories(dir);
    writeText(dir / "deep.json", "{\"name\": " + std::string(5000, '[') + std::string(5000, ']') + "}");
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "deep.json").string()), "JSON nested deeper than 128 levels"));
    // Three fogs of 2^24 voxels (each allowed, seconds to fill): refused before any is built.
    std::string fogs;
    for (int k = 0; k < 3; ++k)
        fogs += std::string(k ? ", " : "") +
                R"({"procedural": "fog", "bounds": [[0, 0, 0], [255, 255, 255]], "voxelSize": 1, "density": 1})";
    writeText(dir / "fogs.json", R"({"gltf": [], "volumes": [)" + fogs + "]}");
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "fogs.json").string()), "voxels in all"));
    // 10 keys of 10 values: 1e10 points, from a few hundred bytes.
    std::string grid;
    const char* keys[] = {"cache.hitLatency",
                          "dram.latency",
                          "memory.latency",
                          "shader.anyHitLatency",
                          "shader.intersectionLatency",
                          "shader.nextTraceLatency",
                          "transform.latency",
                          "traversal.latency",
                          "triangle.latency",
                          "l2.hitLatency"};
    for (int k = 0; k < 10; ++k) {
        grid += std::string(k ? ", " : "") + "\"" + keys[k] + "\": [";
        for (int v = 0; v < 10; ++v) grid += std::string(v ? ", " : "") + std::to_string(v + 1);
        grid += "]";
    }
    writeText(dir / "huge_study.json",
              R"({"workloads": ["builtin:cornell"], "render": {"backend": "rtcore"}, "grid": {)" + grid + "}}");
    EXPECT_TRUE(refused(runCli("sweep " + (dir / "huge_study.json").string() + " --out " + (dir / "sweep").string()),
                        "points (workloads x override sets); at most 100000"));
    writeText(dir / "huge_model.json",
              R"({"gpu": {"cores": 256}, "cache": {"sizeBytes": 1073741824, "lineBytes": 64}})");
    EXPECT_TRUE(refused(runCli("render --scene builtin:cornell --backend rtcore --width 4 --height 4 --rtcore-config " +
                               (dir / "huge_model.json").string() + " --out " + (dir / "out").string()),
                        "cache lines in all"));
}

// A glTF whose one primitive is a sequential Draco mesh (bitstream 2.2) of
// one face declaring `pointsVarint` points (Draco allocates its declared
// count), with POSITION (3 points) and, when texcoordCount > 0, a TEXCOORD_0
// accessor of that many elements, both named by the Draco extension.
std::string dracoGltf(const std::string& pointsVarint, std::uint64_t texcoordCount) {
    std::string draco = std::string("DRACO\x02\x02\x01\x00\x00\x00", 11);
    draco += "\x01" + pointsVarint + std::string("\x01\x00\x01\x02", 4);  // varints: 1 face, the points
    draco += std::string(16, '\0');
    draco += std::string((4 - draco.size() % 4) % 4, '\0');
    static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string b64;
    for (std::size_t i = 0; i < draco.size(); i += 3) {
        const unsigned v = (unsigned char)draco[i] << 16 |
                           (i + 1 < draco.size() ? (unsigned char)draco[i + 1] << 8 : 0) |
                           (i + 2 < draco.size() ? (unsigned char)draco[i + 2] : 0);
        b64 += kAlphabet[v >> 18 & 63];
        b64 += kAlphabet[v >> 12 & 63];
        b64 += i + 1 < draco.size() ? kAlphabet[v >> 6 & 63] : '=';
        b64 += i + 2 < draco.size() ? kAlphabet[v & 63] : '=';
    }
    const std::string n = std::to_string(draco.size());
    const bool uv = texcoordCount > 0;
    return R"({"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_draco_mesh_compression"],)"
           R"( "extensionsRequired": ["KHR_draco_mesh_compression"],)"
           R"( "buffers": [{"uri": "data:application/octet-stream;base64,)" +
           b64 + R"(", "byteLength": )" + n + R"(}], "bufferViews": [{"buffer": 0, "byteLength": )" + n +
           R"(}], "accessors": [{"componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0],)"
           R"( "max": [1, 1, 1]}, {"componentType": 5125, "count": 3, "type": "SCALAR"})" +
           (uv ? R"(, {"componentType": 5126, "count": )" + std::to_string(texcoordCount) + R"(, "type": "VEC2"})"
               : std::string()) +
           R"(], "meshes": [{"primitives": [{"attributes": {"POSITION": 0)" + (uv ? R"(, "TEXCOORD_0": 2)" : "") +
           R"(}, "indices": 1, "extensions": {"KHR_draco_mesh_compression": {"bufferView": 0, "attributes":)"
           R"( {"POSITION": 0)" +
           (uv ? R"(, "TEXCOORD_0": 1)" : "") +
           R"(}}}}]}], "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0})";
}

TEST(CliInputLimits, DracoPointCountsBeyondTheAccessorsAreRefusedBeforeDecoding) {
    const fs::path dir = freshDir("limits_draco");
    fs::create_directories(dir);
    writeText(dir / "points.gltf", dracoGltf(std::string("\xff\xff\xff\xff\x07", 5), 0));  // 2^31 - 1
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "points.gltf").string()),
                        "the Draco data declares 2147483647 points, more than its accessors' 3"));
    // Every accessor must hold the decoded points: a large count on one attribute
    // (1e8 texture coordinates, within the geometry budget) allows no more than the smallest.
    writeText(dir / "uv.gltf", dracoGltf(std::string("\x80\xc2\xd7\x2f", 4), 100000000));  // 1e8
    EXPECT_TRUE(refused(runCli("info --scene " + (dir / "uv.gltf").string()),
                        "the Draco data declares 100000000 points, more than its accessors' 3"));
}

TEST(CliInputLimits, ExrWindowsBeyondTheFileSizeAreRefusedBeforeAllocating) {
    const fs::path dir = freshDir("limits_exr");
    ASSERT_EQ(
        runCli("render --scene builtin:cornell --width 8 --height 8 --denoise none --out " + dir.string()).exitCode, 0);
    std::ifstream in(dir / "frame_0000.exr", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::string attribute = std::string("dataWindow\0box2i\0", 17);
    const std::size_t at = bytes.find(attribute);
    ASSERT_NE(at, std::string::npos);
    const std::int32_t window[4] = {0, 0, 99999, 7};  // 8e5 pixels of 36 channels (the same chunks), from 5 KB
    std::memcpy(&bytes[at + attribute.size() + 4], window, sizeof window);
    writeText(dir / "huge.exr", bytes);
    EXPECT_TRUE(refused(runCli("compare " + (dir / "huge.exr").string() + " " + (dir / "frame_0000.exr").string()),
                        "more than its"));
}

TEST(CliInputLimits, RayTraceBatchesOfTooManyLanesAreRefused) {
    const fs::path dir = freshDir("limits_rays");
    ASSERT_EQ(runCli("render --scene builtin:cornell --width 8 --height 8 --effects gbuffer --denoise none "
                     "--record-rays " +
                     (dir / "rays").string() + " --out " + (dir / "out").string())
                  .exitCode,
              0);
    std::ifstream in(dir / "rays" / "frame_0000.rays", std::ios::binary);
    std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    auto* header = reinterpret_cast<study::RayTraceHeader*>(bytes.data());
    auto* first = reinterpret_cast<study::BatchRecord*>(bytes.data() + sizeof(study::RayTraceHeader));
    header->laneCount += 100000 - first->lanes;
    first->lanes = 100000;
    study::Fnv64 sum;
    sum.add(bytes.data() + sizeof(study::RayTraceHeader), header->bodyBytes);
    header->bodyChecksum = sum.value();
    std::ofstream(dir / "lanes.rays", std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
    EXPECT_TRUE(refused(runCli("replay --scene builtin:cornell --rays " + (dir / "lanes.rays").string() + " --out " +
                               (dir / "replay").string()),
                        "has 100000 lanes, more than the format's 65536"));
}

TEST(CliInputLimits, AnObjFaceOfMoreThan255CornersIsTriangulatedByTinyobjloader) {
    // tinyobjloader counts a kept face's corners in a byte: 300 corners would become 44, every later face shifted.
    const fs::path dir = freshDir("limits_polygon");
    fs::create_directories(dir);
    for (const int corners : {255, 300}) {
        std::string obj, face = "f";
        for (int i = 0; i < corners; ++i) {
            const double a = 6.283185307179586 * i / corners;
            obj.append("v ").append(std::to_string(std::cos(a))).append(" ").append(std::to_string(std::sin(a)));
            obj.append(" 0\n");
            face.append(" ").append(std::to_string(i + 1));
        }
        const fs::path file = dir / ("circle" + std::to_string(corners) + ".obj");
        writeText(file, obj + face + "\nf 1 2 3\n");
        const CliRun r = runCli("info --scene " + file.string());
        ASSERT_EQ(r.exitCode, 0) << r.out;
        // corners - 2 triangles, and the last face's one.
        EXPECT_NE(r.out.find("triangles: " + std::to_string(corners - 1) + " unique"), std::string::npos) << r.out;
        EXPECT_EQ(r.out.find("triangulated by tinyobjloader") != std::string::npos, corners > 255) << r.out;
    }
}

}  // namespace
}  // namespace rtlab::test
