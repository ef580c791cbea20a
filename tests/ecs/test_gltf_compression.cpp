// Compressed and quantized glTF geometry decodes to the triangles of the
// uncompressed data: KHR_draco_mesh_compression on Debian's assimp test model,
// EXT_meshopt_compression and KHR_mesh_quantization on files written here
// (meshoptimizer's own encoders), each compared with the plain file.
#include "gltf_test_util.hpp"

#include <rtlab/ecs/load/mesh_builders.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <gtest/gtest.h>
#include <meshoptimizer.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace rtlab::test {
namespace {

using namespace ecs;
namespace fs = std::filesystem;
using Json = nlohmann::json;

// ---------------------------------------------------------------------------
// KHR_draco_mesh_compression
// ---------------------------------------------------------------------------

struct Summary {
    std::vector<std::size_t> trianglesPerMesh;
    std::vector<std::size_t> degeneratePerMesh;
    std::size_t instances = 0;
    Aabb bounds;
};

Summary summarize(const fs::path& path) {
    World world;
    load::loadGltf(world, path);
    Summary s;
    for (const MeshAsset& m : world.meshes()) {
        s.trianglesPerMesh.push_back(m.triangleCount());
        s.degeneratePerMesh.push_back(load::degenerateTriangleCount(m));
        for (const Geometry& g : m.geometries) {
            EXPECT_EQ(g.normals.size(), g.positions.size());
            for (const vec3& n : g.normals) EXPECT_NEAR(glm::length(n), 1.f, 1e-3f);
        }
    }
    s.instances = world.count<MeshInstance>();
    s.bounds = load::worldBounds(world);
    return s;
}

TEST(GltfDraco, TwoCylinderEngineHasTheGlbsNonDegenerateTrianglesAndBounds) {
    if (!fs::is_directory(kModels)) GTEST_SKIP() << "assimp-testmodels not installed (scripts/install-deps.sh)";
    const Summary draco = summarize(kModels / "draco/2CylinderEngine.gltf");
    const Summary glb = summarize(kModels / "2CylinderEngine-glTF-Binary/2CylinderEngine.glb");
    ASSERT_FALSE(glb.trianglesPerMesh.empty());
    // Draco's encoder dropped the .glb's zero-area triangles (10419 of 75730,
    // mostly a repeated index): mesh by mesh, the Draco file has exactly the
    // others. (Quantization collapses a handful of those again.)
    ASSERT_EQ(draco.trianglesPerMesh.size(), glb.trianglesPerMesh.size());
    std::size_t dropped = 0, collapsed = 0;
    for (std::size_t m = 0; m < glb.trianglesPerMesh.size(); ++m) {
        EXPECT_EQ(draco.trianglesPerMesh[m], glb.trianglesPerMesh[m] - glb.degeneratePerMesh[m]) << m;
        dropped += glb.degeneratePerMesh[m];
        collapsed += draco.degeneratePerMesh[m];
    }
    EXPECT_GT(dropped, 0u);
    EXPECT_LT(collapsed, dropped / 100);
    EXPECT_EQ(draco.instances, glb.instances);
    // Draco quantizes positions: the bounds agree to a small fraction of the extent.
    const float tolerance = 1e-3f * glm::length(glb.bounds.extent());
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(draco.bounds.lo[c], glb.bounds.lo[c], tolerance) << c;
        EXPECT_NEAR(draco.bounds.hi[c], glb.bounds.hi[c], tolerance) << c;
    }
}

class GltfCompressionFiles : public ScratchDirTest {};

TEST_F(GltfCompressionFiles, CorruptDracoDataIsAnInputErrorNamingTheFile) {
    if (!fs::is_directory(kModels)) GTEST_SKIP() << "assimp-testmodels not installed (scripts/install-deps.sh)";
    fs::copy_file(kModels / "draco/2CylinderEngine.gltf", file("engine.gltf"));
    std::ifstream in(kModels / "draco/2CylinderEngine.bin", std::ios::binary);
    std::string bin((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_GT(bin.size(), 64u);
    std::memset(bin.data(), 0, 64);  // the first primitive's Draco header
    std::ofstream(file("2CylinderEngine.bin"), std::ios::binary) << bin;
    const std::string err = loadError(file("engine.gltf"));
    EXPECT_NE(err.find("engine.gltf"), std::string::npos) << err;
    EXPECT_NE(err.find("KHR_draco_mesh_compression"), std::string::npos) << err;
}

// ---------------------------------------------------------------------------
// EXT_meshopt_compression (+ KHR_mesh_quantization for octahedral normals)
// ---------------------------------------------------------------------------

// An icosphere (642 vertices, 1280 triangles), as plain float data.
struct TestMesh {
    std::vector<vec3> positions, normals;
    std::vector<std::uint16_t> indices;
};

TestMesh icosphere() {
    const Geometry g = load::makeIcosphere(2.f, 3, 0);
    TestMesh m;
    m.positions = g.positions;
    m.normals = g.normals;
    for (std::uint32_t i : g.indices) m.indices.push_back(static_cast<std::uint16_t>(i));
    return m;
}

void addPrimitive(GltfBuilder& b, int position, int normal, int indices) {
    b.mesh(Json::array({{{"attributes", {{"POSITION", position}, {"NORMAL", normal}}}, {"indices", indices}}}));
    b.node({{"mesh", 0}});
}

GltfBuilder plainFile(const TestMesh& m) {
    GltfBuilder b;
    const int pos = b.positions(m.positions);
    const int nrm = b.positions(m.normals);
    addPrimitive(b, pos, nrm, b.indices(m.indices));
    return b;
}

// The same mesh with every bufferView meshopt-compressed into buffer 0 and
// decoded into a fallback buffer 1: positions (ATTRIBUTES), indices
// (TRIANGLES), normals as 8-bit octahedral (ATTRIBUTES + OCTAHEDRAL filter,
// normalized byte VEC3: KHR_mesh_quantization). `filtered` uses the other
// codecs instead: EXPONENTIAL positions, 32-bit INDICES (an index sequence),
// 16-bit OCTAHEDRAL normals. `corrupt` breaks the position stream's header.
struct MeshoptOptions {
    bool filtered = false;
    bool corrupt = false;
};
GltfBuilder meshoptFile(const TestMesh& m, MeshoptOptions options = {}) {
    const std::size_t n = m.positions.size(), k = m.indices.size();
    const std::size_t indexSize = options.filtered ? 4 : 2, octSize = options.filtered ? 8 : 4;
    const std::size_t posBytes = n * 12, idxBytes = (k * indexSize + 3) / 4 * 4, nrmBytes = n * octSize;
    GltfBuilder b;
    const int fallback = b.addFallbackBuffer(posBytes + idxBytes + nrmBytes);
    std::size_t fallbackOffset = 0;
    auto view = [&](std::vector<unsigned char> encoded, std::size_t count, std::size_t stride, const char* mode,
                    const char* filter, bool attributes) {
        const std::size_t offset = b.appendBytes(encoded.data(), encoded.size());
        Json ext = {{"buffer", 0},          {"byteOffset", offset}, {"byteLength", encoded.size()},
                    {"byteStride", stride}, {"count", count},       {"mode", mode}};
        if (filter) ext["filter"] = filter;
        Json v = {{"buffer", fallback},
                  {"byteOffset", fallbackOffset},
                  {"byteLength", count * stride},
                  {"extensions", {{"EXT_meshopt_compression", ext}}}};
        if (attributes) v["byteStride"] = stride;
        fallbackOffset += (count * stride + 3) / 4 * 4;
        b.doc()["bufferViews"].push_back(v);
        return static_cast<int>(b.doc()["bufferViews"].size() - 1);
    };
    auto encodeVertices = [](const void* data, std::size_t count, std::size_t stride) {
        std::vector<unsigned char> out(meshopt_encodeVertexBufferBound(count, stride));
        out.resize(meshopt_encodeVertexBuffer(out.data(), out.size(), data, count, stride));
        return out;
    };

    std::vector<unsigned char> pos;
    if (options.filtered) {
        std::vector<std::uint32_t> exp(n * 3);
        meshopt_encodeFilterExp(exp.data(), n, 12, 20, &m.positions[0].x);
        pos = encodeVertices(exp.data(), n, 12);
    } else {
        pos = encodeVertices(m.positions.data(), n, 12);
    }
    if (options.corrupt) pos[0] = 0;
    const int posView = view(pos, n, 12, "ATTRIBUTES", options.filtered ? "EXPONENTIAL" : nullptr, true);

    const std::vector<unsigned int> idx32(m.indices.begin(), m.indices.end());
    std::vector<unsigned char> idx;
    if (options.filtered) {
        idx.resize(meshopt_encodeIndexSequenceBound(k, n));
        idx.resize(meshopt_encodeIndexSequence(idx.data(), idx.size(), idx32.data(), k));
    } else {
        idx.resize(meshopt_encodeIndexBufferBound(k, n));
        idx.resize(meshopt_encodeIndexBuffer(idx.data(), idx.size(), idx32.data(), k));
    }
    const int idxView = view(idx, k, indexSize, options.filtered ? "INDICES" : "TRIANGLES", nullptr, false);

    std::vector<float> normal4;
    for (const vec3& v : m.normals) normal4.insert(normal4.end(), {v.x, v.y, v.z, 1.f});
    std::vector<std::uint8_t> oct(n * octSize);
    meshopt_encodeFilterOct(oct.data(), n, octSize, options.filtered ? 16 : 8, normal4.data());
    const int nrmView = view(encodeVertices(oct.data(), n, octSize), n, octSize, "ATTRIBUTES", "OCTAHEDRAL", true);

    const int posAcc = b.addAccessor(posView, 5126, n, "VEC3");
    const int nrmAcc = b.addAccessor(nrmView, options.filtered ? 5122 : 5120, n, "VEC3");
    b.doc()["accessors"][nrmAcc]["normalized"] = true;
    const int idxAcc = b.addAccessor(idxView, options.filtered ? 5125 : 5123, k, "SCALAR");
    addPrimitive(b, posAcc, nrmAcc, idxAcc);
    b.doc()["extensionsUsed"] = {"EXT_meshopt_compression", "KHR_mesh_quantization"};
    b.doc()["extensionsRequired"] = {"EXT_meshopt_compression", "KHR_mesh_quantization"};
    return b;
}

// Triangles with their first index the smallest: the meshopt index codec
// may rotate a triangle's vertices (keeping its winding).
std::vector<std::uint32_t> canonicalTriangles(std::vector<std::uint32_t> indices) {
    for (std::size_t t = 0; t + 2 < indices.size(); t += 3)
        while (indices[t] > indices[t + 1] || indices[t] > indices[t + 2])
            std::rotate(indices.begin() + t, indices.begin() + t + 1, indices.begin() + t + 3);
    return indices;
}

void expectSameTriangles(const Geometry& decoded, const Geometry& plain, float normalTolerance,
                         float positionTolerance = 0.f) {
    EXPECT_EQ(canonicalTriangles(decoded.indices), canonicalTriangles(plain.indices));
    ASSERT_EQ(decoded.positions.size(), plain.positions.size());
    for (std::size_t i = 0; i < plain.positions.size(); ++i)  // the vertex codec itself is lossless
        ASSERT_LE(glm::length(decoded.positions[i] - plain.positions[i]), positionTolerance) << i;
    ASSERT_EQ(decoded.normals.size(), plain.normals.size());
    for (std::size_t i = 0; i < plain.normals.size(); ++i)
        ASSERT_LT(glm::length(decoded.normals[i] - plain.normals[i]), normalTolerance) << i;
}

TEST_F(GltfCompressionFiles, MeshoptDecodesToThePlainTriangles) {
    const TestMesh mesh = icosphere();
    World plain;
    load::loadGltf(plain, plainFile(mesh).write(file("plain.gltf")));
    ASSERT_EQ(plain.mesh(0).triangleCount(), 1280u);
    GltfBuilder compressed = meshoptFile(mesh);
    for (const fs::path& p : {compressed.write(file("meshopt.gltf")), compressed.writeGlb(file("meshopt.glb"))}) {
        SCOPED_TRACE(p.string());
        World world;
        load::loadGltf(world, p);
        ASSERT_EQ(world.meshes().size(), 1u);
        // 8-bit octahedral normals: within ~1/64 of the float ones.
        expectSameTriangles(world.mesh(0).geometries.at(0), plain.mesh(0).geometries.at(0), 0.03f);
    }
}

TEST_F(GltfCompressionFiles, MeshoptFiltersAndIndexSequencesDecode) {
    const TestMesh mesh = icosphere();
    World plain, world;
    load::loadGltf(plain, plainFile(mesh).write(file("plain.gltf")));
    load::loadGltf(world, meshoptFile(mesh, {.filtered = true}).write(file("filtered.gltf")));
    // 20-bit exponential positions (radius 2: within ~4e-6), the index
    // sequence as it was, 16-bit octahedral normals.
    const Geometry& g = world.mesh(0).geometries.at(0);
    EXPECT_EQ(g.indices, plain.mesh(0).geometries.at(0).indices);
    expectSameTriangles(g, plain.mesh(0).geometries.at(0), 1e-3f, 1e-5f);
}

TEST_F(GltfCompressionFiles, CorruptMeshoptDataIsAnInputError) {
    const std::string err = loadError(meshoptFile(icosphere(), {.corrupt = true}).write(file("broken.gltf")));
    EXPECT_NE(err.find("broken.gltf"), std::string::npos) << err;
    EXPECT_NE(err.find("EXT_meshopt_compression"), std::string::npos) << err;
}

TEST_F(GltfCompressionFiles, MeshoptViewLargerThanItsBufferViewIsAnInputError) {
    GltfBuilder b = meshoptFile(icosphere());
    b.doc()["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = 100000;
    const std::string err = loadError(b.write(file("big.gltf")));
    EXPECT_NE(err.find("exceed the bufferView"), std::string::npos) << err;
}

TEST_F(GltfCompressionFiles, MeshoptFallbackBufferMisuseIsRefusedBeforeAllocating) {
    const fs::path p = meshoptFile(icosphere()).write(file("huge.gltf"));
    const Json original = Json::parse(std::ifstream(p));
    // 1.9 GB claimed from a few kB of compressed positions: refused, not allocated.
    Json doc = original;
    doc["buffers"][1]["byteLength"] = 2000000000;
    doc["bufferViews"][0]["byteLength"] = 1900000000;
    doc["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = 1900000000 / 12;
    std::ofstream(file("huge.gltf")) << doc.dump();
    std::string err = loadError(file("huge.gltf"));
    EXPECT_NE(err.find("cannot fill the bufferView's 1900000000 bytes"), std::string::npos) << err;
    // Only compressed bufferViews may use a fallback buffer (it has no data).
    doc = original;
    doc["bufferViews"][1].erase("extensions");
    std::ofstream(file("plain.gltf")) << doc.dump();
    err = loadError(file("plain.gltf"));
    EXPECT_NE(err.find("bufferViews[1] is not EXT_meshopt_compression-compressed but uses fallback buffer 1"),
              std::string::npos)
        << err;
}

// The geometry budget grows by the file's buffer bytes (1 GiB + 64 x them),
// not by the fallback buffers meshopt decodes into: those are the decoder's
// output, up to 64 x the compressed bytes, and counting them let a file
// decode 64 x 64 x its bytes. Here the primitives declare just over the
// file's allowance, which the fallback buffer's bytes would have covered.
TEST_F(GltfCompressionFiles, MeshoptFallbackBuffersDoNotRaiseTheGeometryBudget) {
    const fs::path p = meshoptFile(icosphere()).write(file("many.gltf"));
    Json doc = Json::parse(std::ifstream(p));
    const std::uint64_t compressed = doc["buffers"][0]["byteLength"].get<std::uint64_t>();
    const std::uint64_t fallback = doc["buffers"][1]["byteLength"].get<std::uint64_t>();
    const std::uint64_t limit = (std::uint64_t{1} << 30) + 64 * compressed;
    // What one primitive declares, read as 4-byte components: POSITION, NORMAL (VEC3) and the indices.
    std::uint64_t perPrimitive = 0;
    for (const Json& a : doc["accessors"])
        perPrimitive += a["count"].get<std::uint64_t>() * (a["type"] == "VEC3" ? 3 : 1) * 4;
    const std::uint64_t primitives = limit / perPrimitive + 1;
    ASSERT_LT(primitives * perPrimitive, limit + 64 * fallback);  // within the allowance the fallback buffer gave
    const Json primitive = doc["meshes"][0]["primitives"][0];
    doc["meshes"][0]["primitives"] = Json::array();
    for (std::uint64_t i = 0; i < primitives; ++i) doc["meshes"][0]["primitives"].push_back(primitive);
    std::ofstream(p) << doc.dump();
    const std::string err = loadError(p);
    EXPECT_NE(err.find("declare more than " + std::to_string(limit) + " bytes of geometry"), std::string::npos) << err;
}

// ---------------------------------------------------------------------------
// KHR_mesh_quantization
// ---------------------------------------------------------------------------

TEST_F(GltfCompressionFiles, QuantizedAttributesDecodeLikeTheSpecSays) {
    // Positions: normalized shorts (stride 8, as the extension's alignment
    // rule asks); normals: normalized bytes (stride 4); UVs: plain unsigned
    // shorts. One node scales the unit-cube positions back up.
    const std::vector<std::array<std::int16_t, 4>> pos = {{0, 0, 0, 0}, {32767, 0, 0, 0}, {0, -32767, 16384, 0}};
    const std::vector<std::array<std::int8_t, 4>> nrm = {{0, 0, 127, 0}, {0, 0, 127, 0}, {0, 0, -127, 0}};
    const std::vector<std::array<std::uint16_t, 2>> uv = {{0, 0}, {3, 0}, {0, 7}};
    GltfBuilder b;
    const int posView = b.addView(pos.data(), pos.size() * 8), nrmView = b.addView(nrm.data(), nrm.size() * 4);
    b.doc()["bufferViews"][posView]["byteStride"] = 8;
    b.doc()["bufferViews"][nrmView]["byteStride"] = 4;
    const int posAcc = b.addAccessor(posView, 5122, 3, "VEC3");
    const int nrmAcc = b.addAccessor(nrmView, 5120, 3, "VEC3");
    const int uvAcc = b.addAccessor(b.addView(uv.data(), uv.size() * 4), 5123, 3, "VEC2");
    b.doc()["accessors"][posAcc]["normalized"] = true;
    b.doc()["accessors"][nrmAcc]["normalized"] = true;
    b.mesh(Json::array({{{"attributes", {{"POSITION", posAcc}, {"NORMAL", nrmAcc}, {"TEXCOORD_0", uvAcc}}}}}));
    b.node({{"mesh", 0}, {"scale", {4, 4, 4}}});
    b.doc()["extensionsUsed"] = {"KHR_mesh_quantization"};
    b.doc()["extensionsRequired"] = {"KHR_mesh_quantization"};

    World world;
    load::loadGltf(world, b.write(file("quantized.gltf")));
    const Geometry& g = world.mesh(0).geometries.at(0);
    ASSERT_EQ(g.positions.size(), 3u);
    EXPECT_EQ(g.positions[1], vec3(1, 0, 0));
    EXPECT_FLOAT_EQ(g.positions[2].y, -1.f);
    EXPECT_FLOAT_EQ(g.positions[2].z, 16384.f / 32767.f);
    EXPECT_EQ(g.normals[0], vec3(0, 0, 1));
    EXPECT_EQ(g.normals[2], vec3(0, 0, -1));
    EXPECT_EQ(g.uv0[1], vec2(3, 0));
    EXPECT_EQ(g.uv0[2], vec2(0, 7));
    const Aabb bounds = load::worldBounds(world);
    EXPECT_FLOAT_EQ(bounds.hi.x, 4.f);
    EXPECT_FLOAT_EQ(bounds.lo.y, -4.f);

    // The same accessors without the extension are not glTF 2.0.
    b.doc().erase("extensionsUsed");
    b.doc().erase("extensionsRequired");
    const std::string err = loadError(b.write(file("unquantized.gltf")));
    EXPECT_NE(err.find("POSITION"), std::string::npos) << err;
    EXPECT_NE(err.find("expected VEC3 float"), std::string::npos) << err;
}

}  // namespace
}  // namespace rtlab::test
