// glTF loader: real third-party files from Debian's assimp-testmodels (valid
// and malformed) plus small hand-written files with base64 data-URI buffers.
#include "gltf_test_util.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace {

using namespace rtlab;
using namespace rtlab::ecs;
namespace fs = std::filesystem;
using Json = nlohmann::json;
using test::GltfBuilder;

using test::kModels;
using test::loadError;

#define SKIP_WITHOUT_ASSIMP_MODELS()                                                                               \
    do {                                                                                                           \
        if (!fs::is_directory(kModels))                                                                            \
            GTEST_SKIP() << kModels.string() << " is missing: scripts/install-deps.sh installs assimp-testmodels"; \
    } while (0)

std::size_t totalTriangles(const World& world) {
    std::size_t n = 0;
    for (const MeshAsset& m : world.meshes()) n += m.triangleCount();
    return n;
}

// ---------------------------------------------------------------------------
// Real files
// ---------------------------------------------------------------------------

TEST(GltfLoaderAssimpModels, EveryFileLoadsOrThrowsInputErrorQuickly) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    std::vector<fs::path> files;
    for (const auto& entry : fs::recursive_directory_iterator(kModels)) {
        std::string ext = entry.path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
        if (entry.is_regular_file() && (ext == ".gltf" || ext == ".glb")) files.push_back(entry.path());
    }
    std::sort(files.begin(), files.end());
    ASSERT_FALSE(files.empty());
    for (const fs::path& f : files) {
        SCOPED_TRACE(f.string());
        World world;
        const auto start = std::chrono::steady_clock::now();
        try {
            load::loadGltf(world, f);
        } catch (const InputError&) {
            // Fine: malformed input is reported, never crashes.
        } catch (const std::exception& e) {
            ADD_FAILURE() << "unexpected exception type: " << e.what();
        }
        const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        // A one-second budget per file (the slowest takes ~0.2 s under ASan).
        EXPECT_LT(seconds, 1.0);
    }
}

// The files of one scene load share one DecodeBudget (a scene .json's
// entries): geometry and texture pixels already decoded count against the
// next file, which is refused before it decodes.
TEST(GltfLoaderAssimpModels, ADecodeBudgetIsSharedByTheFilesOfOneLoad) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    const std::filesystem::path box = kModels / "BoxTextured-glTF" / "BoxTextured.gltf";
    ecs::World world;
    ecs::load::DecodeBudget budget;
    ecs::load::loadGltf(world, box, ecs::kNullEntity, &budget);
    const std::uint64_t geometry = budget.geometryBytes, buffers = budget.bufferBytes;
    EXPECT_EQ(geometry, 24u * (12 + 12 + 8) + 36u * 4) << "POSITION, NORMAL, TEXCOORD_0 and 36 indices";
    EXPECT_GT(buffers, 0u);
    EXPECT_EQ(budget.pixels, 211u * 211u) << "CesiumLogoFlat.png, 211 x 211";
    // Room for half of the box once its second copy's buffers are added.
    budget.geometryBytes = ecs::load::DecodeBudget::kBaseGeometryBytes +
                           ecs::load::DecodeBudget::kGeometryBytesPerBufferByte * 2 * buffers - geometry / 2;
    try {
        ecs::load::loadGltf(world, box, ecs::kNullEntity, &budget);
        ADD_FAILURE() << "the second box was loaded";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("bytes of geometry, the most it may decode"), std::string::npos)
            << e.what();
    }
    // The same for texture pixels: fewer left than the logo has.
    ecs::load::DecodeBudget pixels;
    pixels.pixels = ecs::load::DecodeBudget::kBasePixels - 100;
    const std::string error = [&] {
        try {
            ecs::load::loadGltf(world, box, ecs::kNullEntity, &pixels);
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string();
    }();
    EXPECT_NE(error.find("the scene's images have"), std::string::npos) << error;
}

TEST(GltfLoaderAssimpModels, TwoCylinderEngineLoads) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    World world;
    const auto roots = load::loadGltf(world, kModels / "2CylinderEngine-glTF-Binary/2CylinderEngine.glb");
    EXPECT_FALSE(roots.empty());
    EXPECT_GT(totalTriangles(world), 0u);
    EXPECT_GT(world.meshes().size(), 1u);
    EXPECT_GT(world.count<MeshInstance>(), 1u);
    for (const MeshAsset& m : world.meshes())
        for (const Geometry& g : m.geometries) {
            ASSERT_EQ(g.normals.size(), g.positions.size());
            ASSERT_EQ(g.indices.size() % 3, 0u);
            for (std::uint32_t i : g.indices) ASSERT_LT(i, g.positions.size());
            for (const vec3& n : g.normals) ASSERT_NEAR(glm::length(n), 1.f, 1e-3f);
            ASSERT_LT(g.material, world.materials().size());
        }
}

TEST(GltfLoaderAssimpModels, AnimatedMorphCubeRefitsWithoutRebuild) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    World world;
    load::loadGltf(world, kModels / "glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf");
    ASSERT_EQ(world.meshes().size(), 1u);
    const MeshAsset& mesh = world.mesh(0);
    ASSERT_FALSE(mesh.geometries.empty());
    EXPECT_EQ(mesh.geometries[0].morphTargets.size(), 2u);
    EXPECT_TRUE(mesh.geometries[0].deformable());
    EXPECT_EQ(mesh.geometries[0].restPositions.size(), mesh.geometries[0].positions.size());
    ASSERT_FALSE(world.animations().empty());
    EXPECT_GT(world.animations()[0].duration(), 0.f);
    EXPECT_EQ(world.count<MorphWeights>(), 1u);

    world.update(0.f);
    const FrameUpdate second = world.update(0.5f);
    EXPECT_NE(std::find(second.refitMeshes.begin(), second.refitMeshes.end(), MeshId{0}), second.refitMeshes.end());
    EXPECT_TRUE(second.rebuiltMeshes.empty());
}

TEST(GltfLoaderAssimpModels, SimpleSkinIsSkinnedAndRefits) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    World world;
    load::loadGltf(world, kModels / "simple_skin/simple_skin.gltf");
    ASSERT_EQ(world.count<Skin>(), 1u);
    MeshId skinnedMesh = 0;
    bool found = false;
    world.each<Skin, MeshInstance>([&](Entity, const Skin& skin, const MeshInstance& inst) {
        EXPECT_EQ(skin.joints.size(), 2u);
        EXPECT_EQ(skin.inverseBindMatrices.size(), 2u);
        for (Entity j : skin.joints) EXPECT_TRUE(world.alive(j));
        skinnedMesh = inst.mesh;
        found = true;
    });
    ASSERT_TRUE(found);
    const Geometry& g = world.mesh(skinnedMesh).geometries.at(0);
    EXPECT_EQ(g.joints.size(), g.positions.size());
    EXPECT_EQ(g.weights.size(), g.positions.size());
    ASSERT_FALSE(world.animations().empty());

    world.update(0.f);
    const FrameUpdate second = world.update(1.f);
    EXPECT_NE(std::find(second.refitMeshes.begin(), second.refitMeshes.end(), skinnedMesh), second.refitMeshes.end());
    EXPECT_TRUE(second.rebuiltMeshes.empty());
}

TEST(GltfLoaderAssimpModels, BoxBadNormalsAreRepaired) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    World world;
    load::loadGltf(world, kModels / "BoxBadNormals-glTF-Binary/BoxBadNormals.glb");
    ASSERT_EQ(world.meshes().size(), 1u);
    for (const Geometry& g : world.mesh(0).geometries)
        for (const vec3& n : g.normals) EXPECT_NEAR(glm::length(n), 1.f, 1e-4f);
}

TEST(GltfLoaderAssimpModels, CamerasBecomeCameraComponents) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    World world;
    load::loadGltf(world, kModels / "cameras/Cameras.gltf");
    EXPECT_EQ(world.count<Camera>(), 2u);  // perspective + orthographic (approximated)
    ASSERT_TRUE(world.alive(world.activeCamera()));
    const Camera* cam = world.get<Camera>(world.activeCamera());
    ASSERT_NE(cam, nullptr);
    EXPECT_FLOAT_EQ(cam->yfov, 0.7f);
    EXPECT_FLOAT_EQ(cam->aspectRatio, 1.f);
}

TEST(GltfLoaderAssimpModels, NoRootNodeFilesLoadNothing) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    for (const char* name : {"TestNoRootNode/NoScene.gltf", "TestNoRootNode/SceneWithoutNodes.gltf"}) {
        SCOPED_TRACE(name);
        World world;
        EXPECT_TRUE(load::loadGltf(world, kModels / name).empty());
        EXPECT_EQ(world.entityCount(), 0u);
    }
}

// Malformed inputs: each must throw an InputError naming the file (and the
// problem). All listed files are genuinely invalid glTF.
TEST(GltfLoaderAssimpModels, MalformedFilesThrowInputErrorNamingTheFile) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    struct Case {
        const char* file;
        const char* expected;  // a fragment of the message
    };
    const Case cases[] = {
        {"IndexOutOfRange/IndexOutOfRange.gltf", "out of range"},
        {"IndexOutOfRange/AllIndicesOutOfRange.gltf", "out of range"},
        {"BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb", "non-finite"},
        {"MissingBin/BoxTextured.gltf", "BoxTextured0.bin"},
        {"RecursiveNodes/RecursiveNodes.gltf", "cycle"},
        {"wrongTypes/badArray.gltf", "primitives: expected an array"},
        {"wrongTypes/badExtension.gltf", "KHR_texture_transform: expected a JSON object"},
        {"wrongTypes/badNumber.gltf", "normalTexture"},
        {"wrongTypes/badObject.gltf", "pbrMetallicRoughness: expected a JSON object"},
        {"wrongTypes/badString.gltf", "name: expected a string"},
        {"wrongTypes/badUint.gltf", "index: expected a non-negative integer"},
        {"SchemaFailures/sceneWrongType.gltf", "scene: expected a non-negative integer"},
        {"IncorrectVertexArrays/Cube.gltf", "exceeds buffers[0]"},
        {"BoxTextured-glTF-techniqueWebGL/BoxTextured.gltf", "KHR_technique_webgl"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.file);
        const fs::path path = kModels / c.file;
        World world;
        try {
            load::loadGltf(world, path);
            ADD_FAILURE() << "expected an InputError";
        } catch (const InputError& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find(path.filename().string()), std::string::npos) << what;
            EXPECT_NE(what.find(c.expected), std::string::npos) << what;
        }
        // A failed load leaves nothing behind.
        EXPECT_EQ(world.entityCount(), 0u);
        EXPECT_TRUE(world.meshes().empty());
        EXPECT_TRUE(world.materials().empty());
    }
}

TEST(GltfLoaderAssimpModels, PrimitiveModeFiles) {
    SKIP_WITHOUT_ASSIMP_MODELS();
    // glTF-Asset-Generator Mesh_PrimitiveMode_NN: 00 and 07 are points, 01-03
    // and 08-10 lines (skipped with one warning, no mesh instance), the rest
    // triangles / strips / fans.
    for (int i = 0; i <= 15; ++i) {
        const std::string name = std::string("glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_") +
                                 (i < 10 ? "0" : "") + std::to_string(i) + ".gltf";
        SCOPED_TRACE(name);
        const bool points = i == 0 || i == 7;
        const bool lines = (i >= 1 && i <= 3) || (i >= 8 && i <= 10);
        World world;
        ASSERT_NO_THROW(load::loadGltf(world, kModels / name));
        const LoadReport& report = world.loadReport();
        EXPECT_EQ(report.skippedPointPrimitives, points ? 1u : 0u);
        EXPECT_EQ(report.skippedLinePrimitives, lines ? 1u : 0u);
        ASSERT_EQ(report.warnings.size(), points || lines ? 1u : 0u);
        if (points || lines) {
            EXPECT_NE(report.warnings[0].find(name), std::string::npos) << report.warnings[0];
            EXPECT_EQ(world.count<MeshInstance>(), 0u);
            EXPECT_EQ(totalTriangles(world), 0u);
        } else {
            EXPECT_EQ(world.count<MeshInstance>(), 1u);
            EXPECT_GT(totalTriangles(world), 0u);
        }
    }
    World world;
    load::loadGltf(world, kModels / "glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_04.gltf");  // strip
    EXPECT_EQ(totalTriangles(world), 2u);
}

// ---------------------------------------------------------------------------
// Hand-written files
// ---------------------------------------------------------------------------

class GltfLoaderFiles : public test::ScratchDirTest {
protected:
    // One triangle-mesh primitive with the given mode and optional indices, in one node.
    fs::path writeSingle(const std::string& name, const std::vector<vec3>& pos, int mode, int indexAccessor,
                         GltfBuilder& b) {
        Json prim = {{"attributes", {{"POSITION", b.positions(pos)}}}, {"mode", mode}};
        if (indexAccessor >= 0) prim["indices"] = indexAccessor;
        const int m = b.mesh(Json::array({prim}));
        b.node({{"mesh", m}, {"name", "n"}});
        b.doc()["scenes"] = Json::array({{{"nodes", {0}}}});
        b.doc()["scene"] = 0;
        return b.write(file(name));
    }

    static vec3 faceNormal(const Geometry& g, std::size_t t) {
        const vec3 a = g.positions[g.indices[3 * t]], b = g.positions[g.indices[3 * t + 1]],
                   c = g.positions[g.indices[3 * t + 2]];
        return glm::normalize(glm::cross(b - a, c - a));
    }
};

TEST_F(GltfLoaderFiles, TriangleStripBecomesConsistentlyWoundList) {
    GltfBuilder b;
    // Quad as a strip: v0 (0,0) v1 (1,0) v2 (0,1) v3 (1,1), all facing +Z.
    const fs::path p = writeSingle("strip.gltf", {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}}, 5, -1, b);
    World world;
    load::loadGltf(world, p);
    ASSERT_EQ(world.meshes().size(), 1u);
    const Geometry& g = world.mesh(0).geometries.at(0);
    EXPECT_EQ(g.indices, (std::vector<std::uint32_t>{0, 1, 2, 1, 3, 2}));
    for (std::size_t t = 0; t < g.triangleCount(); ++t) EXPECT_GT(faceNormal(g, t).z, 0.99f);
}

TEST_F(GltfLoaderFiles, TriangleFanBecomesList) {
    GltfBuilder b;
    const std::vector<vec3> pos = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {-1, 1, 0}};
    const fs::path p = writeSingle("fan.gltf", pos, 6, b.indices(std::vector<std::uint16_t>{0, 1, 2, 3, 4}), b);
    World world;
    load::loadGltf(world, p);
    const Geometry& g = world.mesh(0).geometries.at(0);
    EXPECT_EQ(g.indices, (std::vector<std::uint32_t>{1, 2, 0, 2, 3, 0, 3, 4, 0}));
    for (std::size_t t = 0; t < g.triangleCount(); ++t) EXPECT_GT(faceNormal(g, t).z, 0.99f);
}

TEST_F(GltfLoaderFiles, UInt8IndicesAndGeneratedNormals) {
    GltfBuilder b;
    const std::vector<vec3> pos = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    const fs::path p = writeSingle("u8.gltf", pos, 4, b.indices(std::vector<std::uint8_t>{0, 1, 2, 0, 2, 3}), b);
    World world;
    const auto roots = load::loadGltf(world, p);
    ASSERT_EQ(roots.size(), 1u);
    const Geometry& g = world.mesh(0).geometries.at(0);
    EXPECT_EQ(g.indices, (std::vector<std::uint32_t>{0, 1, 2, 0, 2, 3}));
    ASSERT_EQ(g.normals.size(), 4u);  // no NORMAL attribute: generated
    for (const vec3& n : g.normals) EXPECT_NEAR(n.z, 1.f, 1e-5f);
    EXPECT_TRUE(g.uv0.empty());
    EXPECT_FALSE(g.deformable());
    // A default material was added for the primitive without one.
    ASSERT_EQ(world.materials().size(), 1u);
    EXPECT_EQ(g.material, 0u);
    const Name* name = world.get<Name>(roots[0]);
    ASSERT_NE(name, nullptr);
    EXPECT_EQ(name->value, "n");
}

TEST_F(GltfLoaderFiles, IndexOutOfRangeThrows) {
    GltfBuilder b;
    const fs::path p = writeSingle("oob.gltf", {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, 4,
                                   b.indices(std::vector<std::uint16_t>{0, 1, 3}), b);
    const std::string err = loadError(p);
    EXPECT_NE(err.find("oob.gltf"), std::string::npos) << err;
    EXPECT_NE(err.find("index 3 at position 2 is out of range"), std::string::npos) << err;
}

TEST_F(GltfLoaderFiles, LinesPrimitiveIsSkippedWithOneWarning) {
    GltfBuilder b;
    const fs::path p = writeSingle("lines.gltf", {{0, 0, 0}, {1, 0, 0}}, 1, -1, b);
    World world;
    const auto roots = load::loadGltf(world, p);
    ASSERT_EQ(roots.size(), 1u);  // the node stays, without a mesh instance
    EXPECT_FALSE(world.has<MeshInstance>(roots[0]));
    EXPECT_TRUE(world.meshes().empty());
    EXPECT_EQ(world.loadReport().skippedLinePrimitives, 1u);
    EXPECT_EQ(world.loadReport().skippedPointPrimitives, 0u);
    ASSERT_EQ(world.loadReport().warnings.size(), 1u);
    const std::string& w = world.loadReport().warnings[0];
    EXPECT_NE(w.find("lines.gltf"), std::string::npos) << w;
    EXPECT_NE(w.find("0 points and 1 lines"), std::string::npos) << w;
    EXPECT_EQ(w.find('\n'), std::string::npos);
}

TEST_F(GltfLoaderFiles, MixedPrimitivesKeepTrianglesAndCountTheRest) {
    GltfBuilder b;
    const int pos = b.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    b.mesh(Json::array({{{"attributes", {{"POSITION", pos}}}, {"mode", 0}},
                        {{"attributes", {{"POSITION", pos}}}},
                        {{"attributes", {{"POSITION", pos}}}, {"mode", 3}},
                        {{"attributes", {{"POSITION", pos}}}, {"mode", 2}}}));
    b.node({{"mesh", 0}});
    b.node({{"mesh", 0}});
    World world;
    load::loadGltf(world, b.write(file("mixed.gltf")));
    ASSERT_EQ(world.meshes().size(), 1u);
    ASSERT_EQ(world.mesh(0).geometries.size(), 1u);  // the triangle primitive
    EXPECT_EQ(totalTriangles(world), 1u);
    EXPECT_EQ(world.count<MeshInstance>(), 2u);
    // Counted per glTF mesh, not per instance; one warning for the file.
    EXPECT_EQ(world.loadReport().skippedPointPrimitives, 1u);
    EXPECT_EQ(world.loadReport().skippedLinePrimitives, 2u);
    EXPECT_EQ(world.loadReport().warnings.size(), 1u);
}

TEST_F(GltfLoaderFiles, SkippedPrimitivesAreStillValidated) {
    GltfBuilder b;
    const fs::path p =
        writeSingle("badlines.gltf", {{0, 0, 0}, {1, 0, 0}}, 1, b.indices(std::vector<std::uint16_t>{0, 2}), b);
    const std::string err = loadError(p);
    EXPECT_NE(err.find("badlines.gltf"), std::string::npos) << err;
    EXPECT_NE(err.find("index 2 at position 1 is out of range"), std::string::npos) << err;
}

TEST_F(GltfLoaderFiles, NodeCycleThrows) {
    GltfBuilder b;
    b.node({{"children", {1}}});
    b.node({{"children", {2}}});
    b.node({{"children", {0}}});
    b.doc()["scenes"] = Json::array({{{"nodes", {0}}}});
    const fs::path p = b.write(file("cycle.gltf"));
    const std::string err = loadError(p);
    EXPECT_NE(err.find("cycle.gltf"), std::string::npos) << err;
    EXPECT_NE(err.find("cycle"), std::string::npos) << err;
}

TEST_F(GltfLoaderFiles, NodeWithTwoParentsThrows) {
    GltfBuilder b;
    b.node({{"children", {2}}});
    b.node({{"children", {2}}});
    b.node(Json::object());
    const std::string err = loadError(b.write(file("dag.gltf")));
    EXPECT_NE(err.find("child of both node 0 and node 1"), std::string::npos) << err;
}

TEST_F(GltfLoaderFiles, DeepHierarchyDoesNotRecurse) {
    GltfBuilder b;
    const int depth = 20000;
    for (int i = 0; i < depth; ++i) b.node(i + 1 < depth ? Json{{"children", {i + 1}}} : Json::object());
    World world;
    const auto roots = load::loadGltf(world, b.write(file("deep.gltf")));
    EXPECT_EQ(roots.size(), 1u);
    EXPECT_EQ(world.entityCount(), static_cast<std::uint32_t>(depth));
}

TEST_F(GltfLoaderFiles, DeeplyNestedJsonThrows) {
    // 100000 nested arrays in `extras`: rejected before any recursive parser sees it.
    std::ofstream(file("nested.gltf")) << "{\"asset\":{\"version\":\"2.0\"},\"extras\":" << std::string(100000, '[')
                                       << std::string(100000, ']') << "}";
    const std::string err = loadError(file("nested.gltf"));
    EXPECT_NE(err.find("nested deeper"), std::string::npos) << err;
}

TEST_F(GltfLoaderFiles, AccessorBeyondBufferViewThrows) {
    GltfBuilder b;
    const std::vector<vec3> pos = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    const int view = b.addView(pos.data(), sizeof(vec3) * pos.size());
    const int acc = b.addAccessor(view, 5126, 4, "VEC3");  // one element too many
    b.mesh(Json::array({{{"attributes", {{"POSITION", acc}}}}}));
    b.node({{"mesh", 0}});
    const std::string err = loadError(b.write(file("short.gltf")));
    EXPECT_NE(err.find("exceed bufferView"), std::string::npos) << err;
}

TEST_F(GltfLoaderFiles, WrongAccessorTypeThrows) {
    GltfBuilder b;
    const std::vector<float> xy = {0, 0, 1, 0, 0, 1};
    const int acc = b.addAccessor(b.addView(xy.data(), xy.size() * 4), 5126, 3, "VEC2");
    b.mesh(Json::array({{{"attributes", {{"POSITION", acc}}}}}));
    b.node({{"mesh", 0}});
    const std::string err = loadError(b.write(file("vec2pos.gltf")));
    EXPECT_NE(err.find("POSITION"), std::string::npos) << err;
    EXPECT_NE(err.find("expected VEC3 float"), std::string::npos) << err;
}

TEST_F(GltfLoaderFiles, UnsupportedRequiredExtensionThrows) {
    GltfBuilder b;
    b.doc()["extensionsRequired"] = {"KHR_mesh_quantization", "KHR_texture_basisu"};
    b.doc()["extensionsUsed"] = {"KHR_mesh_quantization", "KHR_texture_basisu"};
    const std::string err = loadError(b.write(file("ext.gltf")));
    EXPECT_NE(err.find("unsupported glTF extension KHR_texture_basisu"), std::string::npos) << err;
}

TEST_F(GltfLoaderFiles, WrongFileExtensionThrows) {
    std::ofstream(file("scene.obj")) << "{}";
    EXPECT_NE(loadError(file("scene.obj")).find("scene.obj"), std::string::npos);
    EXPECT_NE(loadError(file("missing.gltf")).find("missing.gltf"), std::string::npos);
    std::ofstream(file("garbage.glb")) << "not a glb at all";
    EXPECT_NE(loadError(file("garbage.glb")).find("garbage.glb"), std::string::npos);
    std::ofstream(file("bad.GLTF")) << "{ \"asset\": ";
    EXPECT_NE(loadError(file("bad.GLTF")).find("invalid JSON"), std::string::npos);
}

TEST_F(GltfLoaderFiles, WithoutSceneParentlessNodesAreRoots) {
    GltfBuilder b;
    b.node({{"name", "a"}, {"children", {2}}});
    b.node({{"name", "b"}, {"translation", {1, 2, 3}}});
    b.node({{"name", "c"}});
    World world;
    const Entity group = world.create("group");
    const auto roots = load::loadGltf(world, b.write(file("noscene.gltf")), group);
    ASSERT_EQ(roots.size(), 2u);
    EXPECT_EQ(world.get<Name>(roots[0])->value, "a");
    EXPECT_EQ(world.get<Name>(roots[1])->value, "b");
    for (Entity r : roots) {
        ASSERT_NE(world.get<Parent>(r), nullptr);
        EXPECT_EQ(world.get<Parent>(r)->entity, group);
    }
    EXPECT_EQ(world.get<LocalTransform>(roots[1])->translation, vec3(1, 2, 3));
    EXPECT_EQ(world.entityCount(), 4u);
}

TEST_F(GltfLoaderFiles, MatrixNodesAreDecomposed) {
    GltfBuilder b;
    // Translation (1,2,3), 90 degrees about Z, scale 2 - column-major.
    b.node({{"matrix", {0, 2, 0, 0, -2, 0, 0, 0, 0, 0, 2, 0, 1, 2, 3, 1}}});
    World world;
    const auto roots = load::loadGltf(world, b.write(file("matrix.gltf")));
    const LocalTransform* t = world.get<LocalTransform>(roots.at(0));
    ASSERT_NE(t, nullptr);
    const mat4 m = t->matrix();
    const mat4 expected(vec4(0, 2, 0, 0), vec4(-2, 0, 0, 0), vec4(0, 0, 2, 0), vec4(1, 2, 3, 1));
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) EXPECT_NEAR(m[c][r], expected[c][r], 1e-5f);
}

TEST_F(GltfLoaderFiles, SharedMeshesRigidSharedDeformableCopied) {
    GltfBuilder b;
    const int pos = b.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    const int delta = b.positions({{0, 0, 1}, {0, 0, 1}, {0, 0, 1}});
    b.mesh(Json::array({{{"attributes", {{"POSITION", pos}}}}}), "rigid");
    b.doc()["meshes"].push_back({{"name", "morph"},
                                 {"weights", {0.25}},
                                 {"primitives", Json::array({{{"attributes", {{"POSITION", pos}}},
                                                              {"targets", Json::array({{{"POSITION", delta}}})}}})}});
    for (int i = 0; i < 2; ++i) b.node({{"mesh", 0}});
    b.node({{"mesh", 1}});
    b.node({{"mesh", 1}, {"weights", {0.5}}});
    World world;
    const auto roots = load::loadGltf(world, b.write(file("shared.gltf")));
    ASSERT_EQ(roots.size(), 4u);
    EXPECT_EQ(world.meshes().size(), 3u);  // rigid shared once, morph mesh copied per instance
    const MeshId r0 = world.get<MeshInstance>(roots[0])->mesh, r1 = world.get<MeshInstance>(roots[1])->mesh;
    const MeshId m0 = world.get<MeshInstance>(roots[2])->mesh, m1 = world.get<MeshInstance>(roots[3])->mesh;
    EXPECT_EQ(r0, r1);
    EXPECT_NE(m0, m1);
    EXPECT_EQ(world.get<MorphWeights>(roots[2])->weights, std::vector<float>{0.25f});
    EXPECT_EQ(world.get<MorphWeights>(roots[3])->weights, std::vector<float>{0.5f});
    const Geometry& g = world.mesh(m1).geometries.at(0);
    ASSERT_EQ(g.morphTargets.size(), 1u);
    EXPECT_EQ(g.morphTargets[0].positionDeltas.size(), 3u);
    EXPECT_EQ(g.restPositions.size(), 3u);

    world.update(0.f);  // morphs are evaluated from the rest pose
    EXPECT_NEAR(world.mesh(m1).geometries[0].positions[0].z, 0.5f, 1e-6f);
    EXPECT_NEAR(world.mesh(m0).geometries[0].positions[0].z, 0.25f, 1e-6f);
}

TEST_F(GltfLoaderFiles, SparseAccessorSubstitutesValues) {
    GltfBuilder b;
    const std::vector<vec3> base = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    const int baseView = b.addView(base.data(), sizeof(vec3) * base.size());
    const std::vector<std::uint8_t> sparseIdx = {2};
    const std::vector<vec3> sparseVal = {{0, 5, 0}};
    const int idxView = b.addView(sparseIdx.data(), 1);
    const int valView = b.addView(sparseVal.data(), sizeof(vec3));
    b.doc()["accessors"].push_back({{"bufferView", baseView},
                                    {"componentType", 5126},
                                    {"count", 3},
                                    {"type", "VEC3"},
                                    {"sparse",
                                     {{"count", 1},
                                      {"indices", {{"bufferView", idxView}, {"componentType", 5121}}},
                                      {"values", {{"bufferView", valView}}}}}});
    b.mesh(Json::array({{{"attributes", {{"POSITION", 0}}}}}));
    b.node({{"mesh", 0}});
    World world;
    load::loadGltf(world, b.write(file("sparse.gltf")));
    const Geometry& g = world.mesh(0).geometries.at(0);
    EXPECT_EQ(g.positions[2], vec3(0, 5, 0));
    EXPECT_EQ(g.positions[1], vec3(1, 0, 0));
}

TEST_F(GltfLoaderFiles, MaterialsCamerasAndLights) {
    GltfBuilder b;
    b.doc()["extensionsUsed"] = {"KHR_lights_punctual", "KHR_materials_transmission", "KHR_materials_ior",
                                 "KHR_materials_volume", "KHR_materials_emissive_strength"};
    b.doc()["extensions"] = {
        {"KHR_lights_punctual",
         {{"lights", Json::array({{{"type", "spot"},
                                   {"color", {1, 0.5, 0.25}},
                                   {"intensity", 10},
                                   {"spot", {{"innerConeAngle", 0.2}, {"outerConeAngle", 0.4}}}}})}}}};
    b.doc()["materials"] = Json::array(
        {{{"name", "glass"},
          {"pbrMetallicRoughness",
           {{"baseColorFactor", {2.0, 0.5, 0.5, 1.0}}, {"metallicFactor", 0.0}, {"roughnessFactor", 0.1}}},
          {"emissiveFactor", {0.5, 0, 0}},
          {"alphaMode", "MASK"},
          {"alphaCutoff", 0.3},
          {"doubleSided", true},
          {"extensions",
           {{"KHR_materials_transmission", {{"transmissionFactor", 0.9}}},
            {"KHR_materials_ior", {{"ior", 1.33}}},
            {"KHR_materials_emissive_strength", {{"emissiveStrength", 4.0}}},
            {"KHR_materials_volume", {{"attenuationColor", {0.5, 0.6, 0.7}}, {"attenuationDistance", 2.0}}}}}}});
    b.doc()["cameras"] = Json::array(
        {{{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.1}, {"aspectRatio", 1.5}}}}});
    const int pos = b.positions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    b.mesh(Json::array({{{"attributes", {{"POSITION", pos}}}, {"material", 0}}}));
    b.node({{"mesh", 0}, {"children", {1, 2}}});
    b.node({{"camera", 0}});
    b.node({{"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
    World world;
    load::loadGltf(world, b.write(file("mat.gltf")));

    ASSERT_EQ(world.materials().size(), 1u);
    const Material& m = world.materials()[0];
    EXPECT_EQ(m.name, "glass");
    EXPECT_EQ(m.baseColor, vec4(1.0f, 0.5f, 0.5f, 1.0f));  // clamped to [0, 1]
    EXPECT_FLOAT_EQ(m.roughness, 0.1f);
    EXPECT_FLOAT_EQ(m.emissive.x, 2.0f);
    EXPECT_EQ(m.alphaMode, AlphaMode::Mask);
    EXPECT_FLOAT_EQ(m.alphaCutoff, 0.3f);
    EXPECT_TRUE(m.doubleSided);
    EXPECT_FLOAT_EQ(m.transmission, 0.9f);
    EXPECT_FLOAT_EQ(m.ior, 1.33f);
    EXPECT_FLOAT_EQ(m.attenuationDistance, 2.0f);
    EXPECT_FLOAT_EQ(m.attenuationColor.z, 0.7f);
    EXPECT_EQ(m.baseColorTexture, kNoTexture);

    ASSERT_TRUE(world.alive(world.activeCamera()));
    const Camera* cam = world.get<Camera>(world.activeCamera());
    EXPECT_FLOAT_EQ(cam->yfov, 0.5f);
    EXPECT_FLOAT_EQ(cam->znear, 0.1f);
    EXPECT_GT(cam->zfar, 1e20f);  // infinite projection
    EXPECT_FLOAT_EQ(cam->aspectRatio, 1.5f);

    ASSERT_EQ(world.count<Light>(), 1u);
    world.each<Light>([](Entity, const Light& l) {
        EXPECT_EQ(l.type, LightType::Spot);
        EXPECT_FLOAT_EQ(l.intensity, 10.f);
        EXPECT_FLOAT_EQ(l.color.y, 0.5f);
        EXPECT_FLOAT_EQ(l.innerConeAngle, 0.2f);
        EXPECT_FLOAT_EQ(l.outerConeAngle, 0.4f);
    });
}

TEST_F(GltfLoaderFiles, AnimationValidation) {
    GltfBuilder b;
    const std::vector<float> times = {0.f, 1.f};
    const std::vector<float> values = {0, 0, 0, 1, 2, 3};
    const int in = b.addAccessor(b.addView(times.data(), 8), 5126, 2, "SCALAR");
    const int out = b.addAccessor(b.addView(values.data(), 24), 5126, 2, "VEC3");
    b.node({{"name", "animated"}});
    b.doc()["animations"] =
        Json::array({{{"channels", Json::array({{{"sampler", 0}, {"target", {{"node", 0}, {"path", "translation"}}}}})},
                      {"samplers", Json::array({{{"input", in}, {"output", out}, {"interpolation", "LINEAR"}}})}}});
    {
        World world;
        const auto roots = load::loadGltf(world, b.write(file("anim.gltf")));
        ASSERT_EQ(world.animations().size(), 1u);
        const AnimationChannel& c = world.animations()[0].channels.at(0);
        EXPECT_EQ(c.target, roots.at(0));
        EXPECT_EQ(c.componentsPerKey, 3u);
        EXPECT_EQ(c.values, values);
        EXPECT_FLOAT_EQ(world.animationDuration(), 1.f);
    }
    // CUBICSPLINE needs 3 values per key: 2 keys x 3 x 3 = 18, we have 6.
    b.doc()["animations"][0]["samplers"][0]["interpolation"] = "CUBICSPLINE";
    EXPECT_NE(loadError(b.write(file("cubic.gltf"))).find("expected 18"), std::string::npos);
    // Target path outside the enum.
    b.doc()["animations"][0]["samplers"][0]["interpolation"] = "LINEAR";
    b.doc()["animations"][0]["channels"][0]["target"]["path"] = "colour";
    EXPECT_NE(loadError(b.write(file("path.gltf"))).find("unsupported target path"), std::string::npos);
    // Target node out of range.
    b.doc()["animations"][0]["channels"][0]["target"] = {{"node", 7}, {"path", "translation"}};
    EXPECT_NE(loadError(b.write(file("node.gltf"))).find("references node 7"), std::string::npos);
}

}  // namespace
