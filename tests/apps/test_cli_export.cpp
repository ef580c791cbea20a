// rtlab export (docs/scene-format.md, "Export"): a builtin workload written as
// OBJ + MTL reads back through the OBJ loader with the same triangles and the
// same bounds bit for bit (shortest round-trip floats), instancing flattened;
// PLY's header and size match its counts; bad --out exits 2 with no file.
#include "cli_test_util.hpp"

#include <cstring>

using namespace rtlab::test;

namespace {

std::string line(const std::string& text, const std::string& key) {
    const std::size_t at = text.find(key);
    return at == std::string::npos ? "" : text.substr(at, text.find('\n', at) - at);
}

}  // namespace

TEST(CliExport, ObjRoundTripsABuiltinWorkload) {
    const fs::path dir = freshDir("export_obj");
    fs::create_directories(dir);
    const std::string scene = "'builtin:terrain?triangles=20000'";
    const CliRun exported = runCli("export --scene " + scene + " --out " + (dir / "terrain.obj").string());
    ASSERT_EQ(exported.exitCode, 0) << exported.out;
    ASSERT_TRUE(fs::exists(dir / "terrain.mtl"));
    const CliRun original = runCli("info --scene " + scene);
    const CliRun reread = runCli("info --scene " + (dir / "terrain.obj").string());
    ASSERT_EQ(reread.exitCode, 0) << reread.out;
    EXPECT_EQ(line(reread.out, "triangles:"), line(original.out, "triangles:"));
    EXPECT_EQ(line(reread.out, "bounds:"), line(original.out, "bounds:"));
    // Forest: 30 instances of a few meshes, flattened into as many objects' triangles.
    const CliRun forest = runCli("export --scene 'builtin:forest?instances=30' --out " + (dir / "forest.obj").string());
    ASSERT_EQ(forest.exitCode, 0) << forest.out;
    const CliRun forestInfo = runCli("info --scene 'builtin:forest?instances=30'");
    const CliRun forestBack = runCli("info --scene " + (dir / "forest.obj").string());
    const std::string instanced = line(forestInfo.out, "triangles:");
    const std::size_t count = std::stoul(instanced.substr(instanced.find(',') + 2));  // "N instanced"
    EXPECT_NE(line(forestBack.out, "triangles:").find(std::to_string(count) + " unique"), std::string::npos)
        << forestBack.out;
    // (Its bounds are the vertices' own: tighter than info's boxes of transformed mesh boxes.)
    // The showcase renders from its export (materials through the MTL).
    const CliRun showcase = runCli("export --scene builtin:showcase --out " + (dir / "showcase.obj").string());
    ASSERT_EQ(showcase.exitCode, 0) << showcase.out;
    const CliRun render = runCli("render --width 16 --height 16 --denoise none --scene " +
                                 (dir / "showcase.obj").string() + " --out " + (dir / "render").string());
    EXPECT_EQ(render.exitCode, 0) << render.out;
}

TEST(CliExport, PlyHeaderMatchesItsBody) {
    const fs::path dir = freshDir("export_ply");
    fs::create_directories(dir);
    const CliRun r = runCli("export --scene builtin:cornell --out " + (dir / "cornell.ply").string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    std::ifstream in(dir / "cornell.ply", std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::size_t end = bytes.find("end_header\n");
    ASSERT_NE(end, std::string::npos);
    const std::string header = bytes.substr(0, end);
    EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);
    const std::size_t vertices = std::stoul(line(header, "element vertex").substr(15));
    const std::size_t faces = std::stoul(line(header, "element face").substr(13));
    EXPECT_GT(faces, 0u);
    EXPECT_EQ(bytes.size() - (end + 11), vertices * 24 + faces * (1 + 12 + 4));
    // Read back through the PLY importer (assimp): the same triangles and bounds as the source.
    const std::string scene = "'builtin:terrain?triangles=20000'";
    ASSERT_EQ(runCli("export --scene " + scene + " --out " + (dir / "terrain.ply").string()).exitCode, 0);
    const CliRun original = runCli("info --scene " + scene);
    const CliRun reread = runCli("info --scene " + (dir / "terrain.ply").string());
    ASSERT_EQ(reread.exitCode, 0) << reread.out;
    EXPECT_EQ(line(reread.out, "triangles:"), line(original.out, "triangles:"));
    EXPECT_EQ(line(reread.out, "bounds:"), line(original.out, "bounds:"));
}

TEST(CliExport, BadOutputExitsTwoAndWritesNothing) {
    const fs::path dir = freshDir("export_bad");
    fs::create_directories(dir);
    const CliRun wrongType = runCli("export --scene builtin:cornell --out " + (dir / "x.stl").string());
    EXPECT_EQ(wrongType.exitCode, 2) << wrongType.out;
    EXPECT_NE(wrongType.out.find(".obj or .ply"), std::string::npos) << wrongType.out;
    const CliRun noDir = runCli("export --scene builtin:cornell --out " + (dir / "missing" / "x.obj").string());
    EXPECT_EQ(noDir.exitCode, 2) << noDir.out;
    EXPECT_EQ(runCli("export --scene nothing.gltf --out " + (dir / "y.obj").string()).exitCode, 2);
    EXPECT_TRUE(fs::is_empty(dir));
}
