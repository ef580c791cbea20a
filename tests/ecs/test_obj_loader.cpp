// The OBJ + MTL loader (docs/scene-format.md, "OBJ and MTL"): literal files
// for what users of the format expect (concave polygons, negative indices,
// groups, per-face materials, the MTL mapping, missing files as warnings),
// and every OBJ of Debian's assimp-testmodels: loads, or an InputError
// naming the file, never another failure.
#include <gtest/gtest.h>

#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/save/scene_writer.hpp>
#include <rtlab/ecs/world.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "../temp_dir.hpp"

using namespace rtlab;
using namespace rtlab::ecs;

namespace {

namespace fs = std::filesystem;

fs::path writeFile(const fs::path& path, const std::string& text) {
    std::ofstream(path, std::ios::binary) << text;
    return path;
}

double area(const Geometry& g) {
    double a = 0.0;
    for (std::size_t t = 0; t + 2 < g.indices.size(); t += 3) {
        const vec3 e1 = g.positions[g.indices[t + 1]] - g.positions[g.indices[t]];
        const vec3 e2 = g.positions[g.indices[t + 2]] - g.positions[g.indices[t]];
        a += 0.5 * double(glm::length(glm::cross(e1, e2)));
    }
    return a;
}

}  // namespace

TEST(ObjLoader, PolygonsGroupsMaterialsAndTheMtlMapping) {
    const fs::path dir = test::freshTempDir("obj_literal");
    fs::create_directories(dir);
    writeFile(dir / "scene.mtl",
              "newmtl red\nKd 0.8 0.1 0.1\nNs 98\nNi 1.33\n"
              "newmtl glass\nKd 1 1 1\nd 0.25\nKe 2 3 4\nmap_Kd missing.png\n");
    // An L-shaped (concave) hexagon of area 3 in the plane z = 0, written with
    // negative (relative) indices; then a second group: a quad in two materials.
    writeFile(dir / "scene.obj",
              "mtllib scene.mtl\n"
              "o floor\n"
              "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\n"
              "usemtl red\n"
              "f -6 -5 -4 -3 -2 -1\n"
              "g walls\n"
              "v 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
              "vn 0 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
              "usemtl red\n"
              "f 7/1/1 8/2/1 9/3/1\n"
              "usemtl glass\n"
              "f 7/1/1 9/3/1 10/4/1\n"
              "l 1 2\n");
    World world;
    const std::vector<Entity> roots = load::loadObj(world, dir / "scene.obj");
    ASSERT_EQ(roots.size(), 2u);
    ASSERT_EQ(world.meshes().size(), 2u);
    // The concave hexagon: 4 triangles covering exactly its area (a fan from corner 0 would not).
    const MeshAsset& floor = world.meshes()[0];
    EXPECT_EQ(floor.name, "floor");
    ASSERT_EQ(floor.geometries.size(), 1u);
    EXPECT_EQ(floor.geometries[0].triangleCount(), 4u);
    EXPECT_NEAR(area(floor.geometries[0]), 3.0, 1e-6);
    for (const vec3& n : floor.geometries[0].normals) EXPECT_NEAR(std::abs(n.z), 1.f, 1e-6f);  // computed
    // The second group: one geometry per material, UVs with v flipped, the file's normals.
    const MeshAsset& walls = world.meshes()[1];
    EXPECT_EQ(walls.name, "walls");
    ASSERT_EQ(walls.geometries.size(), 2u);
    EXPECT_EQ(walls.geometries[0].uv0.size(), walls.geometries[0].positions.size());
    EXPECT_FLOAT_EQ(walls.geometries[0].uv0[0].y, 1.f);
    const Material& red = world.materials()[walls.geometries[0].material];
    const Material& glass = world.materials()[walls.geometries[1].material];
    EXPECT_EQ(red.name, "red");
    EXPECT_FLOAT_EQ(red.baseColor.r, 0.8f);
    EXPECT_NEAR(red.roughness, std::sqrt(2.f / 100.f), 1e-6f);
    EXPECT_FLOAT_EQ(red.ior, 1.33f);
    EXPECT_EQ(red.alphaMode, AlphaMode::Opaque);
    EXPECT_EQ(glass.alphaMode, AlphaMode::Blend);
    EXPECT_FLOAT_EQ(glass.baseColor.a, 0.25f);
    EXPECT_EQ(glass.emissive, vec3(2.f, 3.f, 4.f));
    EXPECT_EQ(glass.baseColorTexture, kNoTexture);
    // The missing texture and the skipped line are warnings naming the file.
    const LoadReport& report = world.loadReport();
    EXPECT_EQ(report.skippedLinePrimitives, 1u);
    bool textureWarning = false;
    for (const std::string& w : report.warnings)
        textureWarning = textureWarning || (w.find("missing.png") != std::string::npos &&
                                            w.find((dir / "scene.obj").string()) != std::string::npos);
    EXPECT_TRUE(textureWarning);
}

// map_d (Sponza's foliage and chains): its grey level becomes the base colour
// texture's alpha, resampled onto map_Kd's texels, or a white texture of its
// own where there is no map_Kd; either way an alpha mask (any-hit).
TEST(ObjLoader, MapDIsTheAlphaMask) {
    const fs::path dir = test::freshTempDir("obj_map_d");
    fs::create_directories(dir);
    writeFile(dir / "mask.pgm", std::string("P5\n2 1\n255\n\xff\x00", 13));
    writeFile(dir / "chain.ppm", std::string("P6\n4 1\n255\n", 11) + std::string(12, '\x80'));
    writeFile(dir / "scene.mtl",
              "newmtl leaf\nKd 0.2 0.8 0.2\nmap_d mask.pgm\n"
              "newmtl chain\nKd 1 1 1\nmap_Kd chain.ppm\nmap_d mask.pgm\n"
              "newmtl lost\nKd 1 1 1\nmap_d nowhere.png\n");
    writeFile(dir / "scene.obj",
              "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
              "usemtl leaf\nf 1/1 2/2 3/3\nusemtl chain\nf 1/1 2/2 3/3\nusemtl lost\nf 1/1 2/2 3/3\n");
    World world;
    load::loadObj(world, dir / "scene.obj");
    ASSERT_EQ(world.meshes().size(), 1u);
    const MeshAsset& mesh = world.meshes()[0];
    ASSERT_EQ(mesh.geometries.size(), 3u);
    const Material& leaf = world.materials()[mesh.geometries[0].material];
    const Material& chain = world.materials()[mesh.geometries[1].material];
    const Material& lost = world.materials()[mesh.geometries[2].material];
    EXPECT_EQ(leaf.alphaMode, AlphaMode::Mask);
    EXPECT_EQ(chain.alphaMode, AlphaMode::Mask);
    EXPECT_EQ(lost.alphaMode, AlphaMode::Opaque);
    ASSERT_LT(leaf.baseColorTexture, world.textures().size());
    const Texture& white = world.textures()[leaf.baseColorTexture];
    EXPECT_EQ(white.rgba8, (std::vector<std::uint8_t>{255, 255, 255, 255, 255, 255, 255, 0}));
    EXPECT_FLOAT_EQ(leaf.baseColor.g, 0.8f);
    ASSERT_LT(chain.baseColorTexture, world.textures().size());
    const Texture& links = world.textures()[chain.baseColorTexture];
    ASSERT_EQ(links.width, 4);
    EXPECT_EQ(links.rgba8,
              (std::vector<std::uint8_t>{128, 128, 128, 255, 128, 128, 128, 255, 128, 128, 128, 0, 128, 128, 128, 0}));
    bool warned = false;
    for (const std::string& w : world.loadReport().warnings)
        warned = warned || w.find("nowhere.png") != std::string::npos;
    EXPECT_TRUE(warned);
}

// Vertex colours ("v x y z r g b") when every vertex has one, clamped to
// [0, 1]; written back by the OBJ export, and read back the same.
TEST(ObjLoader, VertexColoursWhenEveryVertexHasOneAndTheExportKeepsThem) {
    const fs::path dir = test::freshTempDir("obj_colours");
    fs::create_directories(dir);
    writeFile(dir / "all.obj", "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 2\nv 5 5 5 0.5 0.5 0.5\nf 1 2 3\n");
    writeFile(dir / "some.obj", "v 0 0 0 1 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    World all, some, back;
    load::loadObj(all, dir / "all.obj");
    load::loadObj(some, dir / "some.obj");
    const Geometry& g = all.meshes()[0].geometries[0];
    ASSERT_EQ(g.colors.size(), 3u);
    EXPECT_EQ(g.colors[0], vec4(1.f, 0.f, 0.f, 1.f));
    EXPECT_EQ(g.colors[1], vec4(0.f, 1.f, 0.f, 1.f));
    EXPECT_EQ(g.colors[2], vec4(0.f, 0.f, 1.f, 1.f));
    EXPECT_TRUE(some.meshes()[0].geometries[0].colors.empty());
    save::writeObj(all, dir / "back.obj");
    load::loadObj(back, dir / "back.obj");
    EXPECT_EQ(back.meshes()[0].geometries[0].colors, g.colors);
}

TEST(ObjLoader, PointsOrLinesOnlyAreAnEmptySceneWithAWarning) {
    const fs::path dir = test::freshTempDir("obj_points");
    fs::create_directories(dir);
    World world;
    load::loadObj(world, writeFile(dir / "points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\np 1 2 3\nl 1 2\n"));
    EXPECT_TRUE(world.meshes().empty());
    EXPECT_EQ(world.loadReport().skippedLinePrimitives, 1u);
    bool noFaces = false;
    for (const std::string& w : world.loadReport().warnings)
        noFaces = noFaces || w.find("no faces") != std::string::npos;
    EXPECT_TRUE(noFaces);
}

TEST(ObjLoader, BadFilesAreInputErrorsNamingTheFile) {
    const fs::path dir = test::freshTempDir("obj_bad");
    fs::create_directories(dir);
    const auto expectInputError = [&](const std::string& name, const std::string& text, const std::string& what) {
        World world;
        const fs::path p = writeFile(dir / name, text);
        try {
            load::loadObj(world, p);
            ADD_FAILURE() << name << " loaded";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
        }
        EXPECT_TRUE(world.meshes().empty()) << name;  // nothing half-built
    };
    expectInputError("far.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "vertex");
    expectInputError("nothing.obj", "# only a comment\n", "no geometry");
    expectInputError("huge.obj", "v 0 0 1e39\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "finite");
    expectInputError("utf16.obj", std::string("\xfe\xff\0v", 4), "UTF-16");
}

TEST(ObjLoader, EveryAssimpTestModelLoadsOrIsAnInputError) {
    const fs::path models = "/usr/share/assimp/models/OBJ";
    ASSERT_TRUE(fs::is_directory(models)) << "assimp-testmodels is not installed (scripts/install-deps.sh)";
    std::size_t loaded = 0, refused = 0;
    for (const fs::directory_entry& e : fs::directory_iterator(models)) {
        if (e.path().extension() != ".obj") continue;
        World world;
        try {
            load::loadObj(world, e.path());
            std::size_t triangles = 0;
            for (const MeshAsset& m : world.meshes()) triangles += m.triangleCount();
            EXPECT_TRUE(triangles > 0 || !world.loadReport().warnings.empty()) << e.path();  // points or lines only
            ++loaded;
        } catch (const InputError& err) {
            EXPECT_NE(std::string(err.what()).find(e.path().string()), std::string::npos) << err.what();
            ++refused;
        }
    }
    EXPECT_GE(loaded, 15u);
    EXPECT_GE(refused, 1u);  // box_UTF16BE.obj
    // The LightWave concave polygon: one polygon of 66 corners: 64 triangles.
    World world;
    load::loadObj(world, models / "concave_polygon.obj");
    ASSERT_EQ(world.meshes().size(), 1u);
    EXPECT_EQ(world.meshes()[0].triangleCount(), 64u);
    // The spider's textures (written with Windows paths) are found.
    World spider;
    load::loadObj(spider, models / "spider.obj");
    EXPECT_FALSE(spider.textures().empty());
}
