// End-to-end: the rtlab executable's contract (DESIGN.md command line).
#include "cli_test_util.hpp"

#include <cctype>

#include <rtlab/core/image.hpp>

#include <stb_image.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>
#include <sys/wait.h>

namespace fs = std::filesystem;
using namespace rtlab::test;

namespace {

const fs::path kAssimp = "/usr/share/assimp/models/glTF2";

// Renders every file (8x8): those in `exitTwo` (path relative to `root` -> a
// part of the message) must exit 2 with one line naming the file and no
// output; every other one renders. The assimp-testmodels tests share it.
void expectEachRendersOrExitsTwo(const std::vector<fs::path>& files, const fs::path& root,
                                 const std::map<std::string, std::string>& exitTwo) {
    std::size_t rendered = 0, rejected = 0;
    for (const fs::path& f : files) {
        const std::string rel = fs::relative(f, root).string();
        const fs::path out = freshDir("assimp");
        const CliRun r =
            runCli("render --width 8 --height 8 --denoise none --scene " + f.string() + " --out " + out.string());
        const auto expected = exitTwo.find(rel);
        if (expected == exitTwo.end()) {
            EXPECT_EQ(r.exitCode, 0) << rel << "\n" << r.out;
            EXPECT_TRUE(fs::exists(out / "frame_0000.png")) << rel;
            rendered += r.exitCode == 0;
        } else {
            EXPECT_EQ(r.exitCode, 2) << rel << "\n" << r.out;
            EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << rel << "\n" << r.out;
            EXPECT_NE(r.out.find(f.filename().string()), std::string::npos) << rel << "\n" << r.out;
            EXPECT_NE(r.out.find(expected->second), std::string::npos) << rel << "\n" << r.out;
            EXPECT_FALSE(fs::exists(out / "frame_0000.exr")) << rel;
            rejected += r.exitCode == 2;
        }
    }
    EXPECT_EQ(rejected, exitTwo.size());
    EXPECT_EQ(rendered, files.size() - exitTwo.size());
}

}  // namespace

TEST(Cli, RenderShowcaseThreeFramesWritesOutputsAndUpdateCounts) {
    const fs::path out = freshDir("showcase");
    const CliRun r = runCli("render --scene builtin:showcase --frames 3 --width 96 --height 54 --out " + out.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    for (int f = 0; f < 3; ++f) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d", f);
        EXPECT_TRUE(fs::exists(out / (std::string(name) + ".exr")));
        EXPECT_TRUE(fs::exists(out / (std::string(name) + ".png")));
    }
    std::ifstream in(out / "stats.json");
    const nlohmann::json stats = nlohmann::json::parse(in);
    ASSERT_EQ(stats["frames"].size(), 3u);
    EXPECT_GT(stats["frames"][0]["update"]["rebuilt"].get<int>(), 0);
    EXPECT_EQ(stats["frames"][0]["accel"]["tlasBuilds"].get<int>(), 1);
    for (int f = 1; f < 3; ++f) {
        const auto& fr = stats["frames"][f];
        EXPECT_EQ(fr["update"]["moved"].get<int>(), 1) << f;
        EXPECT_EQ(fr["update"]["refit"].get<int>(), 1) << f;
        EXPECT_EQ(fr["update"]["rebuilt"].get<int>(), 0) << f;
        EXPECT_EQ(fr["accel"]["blasRefit"].get<int>(), 1) << f;
        EXPECT_EQ(fr["accel"]["blasRebuilt"].get<int>(), 0) << f;
        EXPECT_EQ(fr["accel"]["tlasBuilds"].get<int>(), 0) << f;
        EXPECT_EQ(fr["accel"]["tlasUpdates"].get<int>(), 1) << f;
        EXPECT_GT(fr["rays"]["primary"]["hits"].get<int>(), 0) << f;
    }
    // The image is not empty: most pixels of a closed room hit something.
    const rtlab::Image img = rtlab::readExr(out / "frame_0002.exr");
    EXPECT_TRUE(img.hasChannel("albedo.R"));
    EXPECT_TRUE(img.hasChannel("depth.Z"));
    EXPECT_EQ(stats["frames"][2]["rays"]["primary"]["misses"].get<int>(), 0);
}

TEST(Cli, OneAndTwoThreadsAreBitIdentical) {
    // The EXR of the second frame and the stats (apart from timing) match.
    const ThreadCountRuns r = renderWithOneAndTwoThreads(
        "showcase", "render --scene builtin:showcase --frames 2 --width 80 --height 45", "frame_0001.exr");
    ASSERT_TRUE(r.rendered()) << r.one.out << r.two.out;
    EXPECT_TRUE(r.framesIdentical()) << r.compare.out;
    EXPECT_EQ(r.statsOne, r.statsTwo);
    EXPECT_GT(r.statsOne["frames"][1]["rays"]["primary"]["traced"].get<int>(), 0);
}

TEST(Cli, CompareReportsDifferences) {
    const fs::path a = freshDir("cmpa"), b = freshDir("cmpb");
    ASSERT_EQ(runCli("render --scene builtin:showcase --width 40 --height 30 --out " + a.string()).exitCode, 0);
    ASSERT_EQ(runCli("render --scene builtin:cornell --width 40 --height 30 --out " + b.string()).exitCode, 0);
    const CliRun cmp = runCli("compare " + (a / "frame_0000.exr").string() + " " + (b / "frame_0000.exr").string());
    EXPECT_EQ(cmp.exitCode, 0);
    EXPECT_NE(cmp.out.find("identical: false"), std::string::npos) << cmp.out;
    EXPECT_NE(cmp.out.find("rmse:"), std::string::npos);
    EXPECT_NE(cmp.out.find("psnr:"), std::string::npos);
    EXPECT_NE(cmp.out.find("relmse:"), std::string::npos);
}

TEST(Cli, BadInputExitsTwoWithOneLineAndNoOutputs) {
    const fs::path out = freshDir("bad");
    const std::vector<std::string> cases = {
        "render --scene builtin:nope --out " + out.string(),
        "render --scene /no/such/file.gltf --out " + out.string(),
        "render --scene builtin:cornell --width 0 --out " + out.string(),
        "render --scene builtin:cornell --backend warp --out " + out.string(),
        "render --scene builtin:cornell --rtcore-set bvh.width=8 --out " + out.string(),  // embree back end
        "render --scene builtin:cornell --verify --out " + out.string(),
        "render --scene builtin:cornell --backend rtcore --rtcore-set bvh.width=5 --out " + out.string(),
        "render --scene builtin:cornell --backend rtcore --rtcore-set nope.x=1 --out " + out.string(),
        "render --scene builtin:cornell --backend rtcore --rtcore-config /no/such/rtcore.json --out " + out.string(),
        "render --scene builtin:cornell --backend rtcore --rtcore-config no-such-preset --out " + out.string(),
        // a parameter set explicitly that has no effect (l2 ideal in the single-core preset; tile mode)
        "render --scene builtin:cornell --backend rtcore --rtcore-config single-core --rtcore-set l2.sizeBytes=65536 "
        "--out " +
            out.string(),
        "render --scene builtin:cornell --backend rtcore --rtcore-set gpu.launch=tile --rtcore-set "
        "gpu.residentWarps=4 --out " +
            out.string(),
        // cross-field rule: the input queue must hold a whole warp
        "render --scene builtin:cornell --backend rtcore --rtcore-set core.inputQueueRays=8 --out " + out.string(),
        "render --scene /no/such/file.gltf --backend rtcore --verify --out " + out.string(),
        "render --scene builtin:cornell --effects ao,glitter --out " + out.string(),
        "render --scene builtin:cornell --denoise svgf --out " + out.string(),
        "render --scene builtin:cornell --denoise , --out " + out.string(),
        "render --scene builtin:cornell --gi photons --out " + out.string(),
        "plan --scene /no/such/file.gltf",
        "plan --scene builtin:cornell --effects nope",
        "render --bogus-flag",
        "frobnicate",
        "compare /no/a.exr /no/b.exr",
        "info --scene " + std::string(RTLAB_SOURCE_DIR) + "/CMakeLists.txt",
    };
    for (const std::string& args : cases) {
        const CliRun r = runCli(args);
        EXPECT_EQ(r.exitCode, 2) << args << "\n" << r.out;
        EXPECT_FALSE(r.out.empty()) << args;
        EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << args << "\n" << r.out;
    }
    EXPECT_FALSE(fs::exists(out / "frame_0000.exr"));
    EXPECT_FALSE(fs::exists(out / "stats.json"));
}

TEST(Cli, InfoOnThirdPartyGltf) {
    if (!fs::exists(kAssimp)) GTEST_SKIP() << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    const CliRun engine =
        runCli("info --scene " + (kAssimp / "2CylinderEngine-glTF-Binary/2CylinderEngine.glb").string());
    ASSERT_EQ(engine.exitCode, 0) << engine.out;
    EXPECT_NE(engine.out.find("triangles:"), std::string::npos);
    const CliRun morph = runCli(
        "info --scene " + (kAssimp / "glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf").string());
    ASSERT_EQ(morph.exitCode, 0) << morph.out;
    EXPECT_EQ(morph.out.find("animations: 0"), std::string::npos) << morph.out;
    const CliRun skin = runCli("info --scene " + (kAssimp / "simple_skin/simple_skin.gltf").string());
    ASSERT_EQ(skin.exitCode, 0) << skin.out;
    EXPECT_NE(skin.out.find("skins: 1"), std::string::npos) << skin.out;
}

TEST(Cli, MalformedThirdPartyGltfExitsTwo) {
    if (!fs::exists(kAssimp)) GTEST_SKIP() << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    for (const char* file :
         {"IndexOutOfRange/IndexOutOfRange.gltf", "BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb",
          "MissingBin/BoxTextured.gltf", "RecursiveNodes/RecursiveNodes.gltf", "wrongTypes/badArray.gltf"}) {
        const fs::path out = freshDir("malformed");
        const CliRun r =
            runCli("render --width 16 --height 16 --scene " + (kAssimp / file).string() + " --out " + out.string());
        EXPECT_EQ(r.exitCode, 2) << file << "\n" << r.out;
        EXPECT_NE(r.out.find(fs::path(file).filename().string()), std::string::npos) << r.out;
        EXPECT_FALSE(fs::exists(out / "frame_0000.exr")) << file;
    }
}

TEST(Cli, RenderThirdPartyGltf) {
    if (!fs::exists(kAssimp)) GTEST_SKIP() << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    const fs::path out = freshDir("engine");
    const CliRun r =
        runCli("render --width 64 --height 48 --scene " +
               (kAssimp / "2CylinderEngine-glTF-Binary/2CylinderEngine.glb").string() + " --out " + out.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    std::ifstream in(out / "stats.json");
    const nlohmann::json stats = nlohmann::json::parse(in);
    EXPECT_GT(stats["frames"][0]["rays"]["primary"]["hits"].get<int>(), 0);
}

// Debian's assimp glTF2 models, every .gltf/.glb: the valid ones render
// (Draco and points/lines files included); the malformed ones, and the one
// that requires an extension outside the supported list, exit 2 with one
// line naming the file and the problem.
TEST(Cli, EveryAssimpObjRendersOrExitsTwoWithOneLine) {
    // Debian's assimp-testmodels: models/OBJ and the OBJ files of models/invalid.
    const fs::path models = "/usr/share/assimp/models";
    ASSERT_TRUE(fs::exists(models / "OBJ")) << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    const std::map<std::string, std::string> exitTwo = {
        {"OBJ/box_UTF16BE.obj", "UTF-16"},
        {"invalid/empty.obj", "no geometry"},
        {"invalid/malformed.obj", "zero value for face index"},
        {"invalid/malformed2.obj", "a face of 0 corner(s)"},
    };
    std::vector<fs::path> files;
    for (const char* dir : {"OBJ", "invalid"})
        for (const auto& e : fs::directory_iterator(models / dir))
            if (e.is_regular_file() && e.path().extension() == ".obj") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    ASSERT_GE(files.size(), 25u);
    expectEachRendersOrExitsTwo(files, models, exitTwo);
}

TEST(Cli, EveryAssimpPlyAndFbxRendersOrExitsTwoWithOneLine) {
    // Debian's assimp-testmodels through assimp: models/PLY, models/FBX (and
    // its embedded_ascii), and the PLY and FBX files of models/invalid.
    const fs::path models = "/usr/share/assimp/models";
    ASSERT_TRUE(fs::exists(models / "PLY")) << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    const std::map<std::string, std::string> exitTwo = {
        {"FBX/transparentTest.fbx", "block offset is out of range"},  // assimp 5.2 rejects it itself
        {"invalid/empty.ply", "is empty"},
    };
    std::vector<fs::path> files;
    for (const auto& e : fs::recursive_directory_iterator(models)) {
        std::string ext = e.path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
        const std::string top = fs::relative(e.path(), models).begin()->string();
        if (e.is_regular_file() && (ext == ".ply" || ext == ".fbx") &&
            (top == "PLY" || top == "FBX" || top == "invalid"))
            files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    ASSERT_GE(files.size(), 27u);
    expectEachRendersOrExitsTwo(files, models, exitTwo);
}

TEST(Cli, EveryAssimpGltfRendersOrExitsTwoWithOneLine) {
    if (!fs::exists(kAssimp)) GTEST_SKIP() << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    const std::map<std::string, std::string> exitTwo = {
        {"BoxTextured-glTF-techniqueWebGL/BoxTextured.gltf", "requires unsupported glTF extension KHR_technique_webgl"},
        {"BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb", "non-finite"},
        {"IncorrectVertexArrays/Cube.gltf", "exceeds buffers[0]"},
        {"IndexOutOfRange/AllIndicesOutOfRange.gltf", "out of range"},
        {"IndexOutOfRange/IndexOutOfRange.gltf", "out of range"},
        {"MissingBin/BoxTextured.gltf", "BoxTextured0.bin"},
        {"RecursiveNodes/RecursiveNodes.gltf", "cycle"},
        {"SchemaFailures/sceneWrongType.gltf", "scene: expected a non-negative integer"},
        {"wrongTypes/badArray.gltf", "expected an array"},
        {"wrongTypes/badExtension.gltf", "expected a JSON object"},
        {"wrongTypes/badNumber.gltf", "normalTexture"},
        {"wrongTypes/badObject.gltf", "expected a JSON object"},
        {"wrongTypes/badString.gltf", "expected a string"},
        {"wrongTypes/badUint.gltf", "expected a non-negative integer"},
    };
    std::vector<fs::path> files;
    for (const auto& e : fs::recursive_directory_iterator(kAssimp))
        if (e.is_regular_file() && (e.path().extension() == ".gltf" || e.path().extension() == ".glb"))
            files.push_back(e.path());
    std::sort(files.begin(), files.end());
    ASSERT_GE(files.size(), 40u);
    expectEachRendersOrExitsTwo(files, kAssimp, exitTwo);
}

// A file with only points or lines: an empty frame, one warning line, the
// skipped primitives counted in stats.json and by `info`.
TEST(Cli, PointsOrLinesOnlyGltfRendersAnEmptyFrameWithOneWarning) {
    if (!fs::exists(kAssimp)) GTEST_SKIP() << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    const fs::path modes = kAssimp / "glTF-Asset-Generator/Mesh_PrimitiveMode";
    const fs::path out = freshDir("points");
    const CliRun r = runCli("render --width 16 --height 16 --scene " + (modes / "Mesh_PrimitiveMode_00.gltf").string() +
                            " --out " + out.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    std::size_t warnings = 0;
    for (std::size_t at = r.out.find("rtlab: warning:"); at != std::string::npos;
         at = r.out.find("rtlab: warning:", at + 1))
        ++warnings;
    EXPECT_EQ(warnings, 1u) << r.out;
    EXPECT_NE(r.out.find("Mesh_PrimitiveMode_00.gltf: skipped 1 points and 0 lines"), std::string::npos) << r.out;
    std::ifstream in(out / "stats.json");
    const nlohmann::json stats = nlohmann::json::parse(in);
    EXPECT_EQ(stats["load"]["skippedPrimitives"]["points"].get<int>(), 1);
    EXPECT_EQ(stats["load"]["skippedPrimitives"]["lines"].get<int>(), 0);
    EXPECT_EQ(stats["frames"][0]["rays"]["primary"]["hits"].get<int>(), 0);
    EXPECT_EQ(stats["frames"][0]["rays"]["primary"]["misses"].get<int>(), 16 * 16);

    const CliRun info = runCli("info --scene " + (modes / "Mesh_PrimitiveMode_08.gltf").string());
    ASSERT_EQ(info.exitCode, 0) << info.out;
    EXPECT_NE(info.out.find("skipped primitives: 0 points, 1 lines"), std::string::npos) << info.out;
    EXPECT_NE(info.out.find("triangles: 0 unique"), std::string::npos) << info.out;
}

// The Draco-compressed engine renders like the uncompressed .glb: `info`
// counts the .glb's triangles minus its degenerate ones (Draco's encoder
// drops those), and nearly the same primary rays hit (Draco quantizes
// positions).
TEST(Cli, DracoGltfRendersLikeTheGlb) {
    if (!fs::exists(kAssimp)) GTEST_SKIP() << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    int hits[2] = {0, 0};
    unsigned long triangles[2] = {0, 0}, instanced[2] = {0, 0}, degenerate[2] = {0, 0};
    const char* files[2] = {"draco/2CylinderEngine.gltf", "2CylinderEngine-glTF-Binary/2CylinderEngine.glb"};
    for (int i = 0; i < 2; ++i) {
        const fs::path out = freshDir("draco" + std::to_string(i));
        const CliRun r = runCli("render --width 48 --height 32 --denoise none --effects gbuffer --scene " +
                                (kAssimp / files[i]).string() + " --out " + out.string());
        ASSERT_EQ(r.exitCode, 0) << files[i] << "\n" << r.out;
        std::ifstream in(out / "stats.json");
        hits[i] = nlohmann::json::parse(in)["frames"][0]["rays"]["primary"]["hits"].get<int>();
        const CliRun info = runCli("info --scene " + (kAssimp / files[i]).string());
        ASSERT_EQ(info.exitCode, 0) << info.out;
        const std::size_t at = info.out.find("triangles:");
        ASSERT_NE(at, std::string::npos) << info.out;
        ASSERT_EQ(std::sscanf(info.out.c_str() + at, "triangles: %lu unique, %lu instanced, %lu", &triangles[i],
                              &instanced[i], &degenerate[i]),
                  3)
            << info.out;
    }
    EXPECT_GT(degenerate[1], 0u);
    EXPECT_LT(degenerate[0], degenerate[1] / 100);  // a few collapsed by Draco's quantization
    EXPECT_EQ(triangles[0], triangles[1] - degenerate[1]);
    EXPECT_GT(hits[1], 48 * 32 / 10);
    EXPECT_NEAR(hits[0], hits[1], hits[1] / 50 + 2);
}

// --backend rtcore: the model traces every ray; --verify traces each again
// on Embree. Images equal Embree's bit for bit; stats carry the model's tree.
TEST(Cli, RtcoreRenderVerifiesAndMatchesEmbree) {
    const fs::path rt = freshDir("rtcore"), em = freshDir("rtcore_embree");
    const std::string common = "render --scene builtin:showcase --frames 2 --width 64 --height 36 ";
    const CliRun r = runCli(common + "--backend rtcore --verify --out " + rt.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    EXPECT_NE(r.out.find(", 0 mismatch(es)"), std::string::npos) << r.out;
    ASSERT_EQ(runCli(common + "--out " + em.string()).exitCode, 0);
    std::ifstream in(rt / "stats.json");
    const nlohmann::json stats = nlohmann::json::parse(in);
    EXPECT_EQ(stats["settings"]["backend"], "rtcore");
    EXPECT_EQ(stats["rtcore"]["config"]["core"]["warpWidth"].get<int>(), 32);
    for (int f = 0; f < 2; ++f) {
        const auto& fr = stats["frames"][f];
        std::uint64_t traced = 0;
        for (const auto& [type, counts] : fr["rays"].items()) traced += counts["traced"].get<std::uint64_t>();
        EXPECT_EQ(fr["rays"]["primary"]["traced"].get<int>(), 64 * 36) << f;
        EXPECT_GT(traced, 4u * 64 * 36) << f;  // every effect traces
        EXPECT_EQ(fr["rtcore"]["verify"]["rays"].get<std::uint64_t>(), traced) << f;
        EXPECT_EQ(fr["rtcore"]["verify"]["mismatches"].get<int>(), 0) << f;
        EXPECT_EQ(fr["rtcore"]["verify"]["notBitIdentical"].get<int>(), 0) << f;
        EXPECT_EQ(fr["rtcore"]["frame"]["rays"].get<std::uint64_t>(), traced) << f;
        EXPECT_GT(fr["rtcore"]["frame"]["cycles"].get<std::uint64_t>(), 0u) << f;
        EXPECT_GT(fr["rtcore"]["rays"]["nodeVisits"]["mean"].get<double>(), 0.0) << f;
        char name[32];
        std::snprintf(name, sizeof name, "frame_%04d", f);
        const std::string n(name);
        const CliRun cmp = runCli("compare " + (rt / (n + ".exr")).string() + " " + (em / (n + ".exr")).string());
        EXPECT_NE(cmp.out.find("identical: true"), std::string::npos) << cmp.out;
        EXPECT_TRUE(fs::exists(rt / (n + "_rtcore_cycles.png")));
        EXPECT_TRUE(fs::exists(rt / (n + "_rtcore_nodes.png")));
        const rtlab::Image heat = rtlab::readExr(rt / (n + "_rtcore.exr"));
        ASSERT_TRUE(heat.hasChannel("rtcore.cycles"));
        ASSERT_TRUE(heat.hasChannel("rtcore.nodeVisits"));
        ASSERT_TRUE(heat.hasChannel("rtcore.slotCycles"));
        const float* cycles = heat.channel("rtcore.cycles");
        const float* slotCycles = heat.channel("rtcore.slotCycles");
        for (std::size_t p = 0; p < heat.pixelCount(); ++p) {
            ASSERT_GT(slotCycles[p], 0.f) << p;
            ASSERT_LE(slotCycles[p], cycles[p]) << p;  // latency = queue waits + time in the slot
        }
    }
    // Frame 1 refits the cloth and moves the box in the model's BVH too.
    EXPECT_EQ(stats["frames"][1]["rtcore"]["bvhUpdate"]["blasRefit"].get<int>(), 1);
    EXPECT_EQ(stats["frames"][1]["rtcore"]["bvhUpdate"]["blasRebuilt"].get<int>(), 0);
}

TEST(Cli, RtcoreOneAndTwoThreadsAreBitIdentical) {
    const ThreadCountRuns r = renderWithOneAndTwoThreads(
        "rtcore", "render --scene builtin:showcase --frames 2 --width 48 --height 32 --backend rtcore",
        "frame_0001_rtcore.exr");
    ASSERT_TRUE(r.rendered()) << r.one.out << r.two.out;
    EXPECT_TRUE(r.framesIdentical()) << r.compare.out;
    // The cycle counts and the whole stats tree, not just the image.
    EXPECT_EQ(r.statsOne, r.statsTwo);
    EXPECT_TRUE(r.statsOne["frames"][1].contains("rtcore"));
}

TEST(Cli, PlanPrintsThePassesAndWhy) {
    const CliRun cornell = runCli("plan --scene builtin:cornell");
    ASSERT_EQ(cornell.exitCode, 0) << cornell.out;
    EXPECT_NE(cornell.out.find("[x] shadows: 1 area light"), std::string::npos) << cornell.out;
    EXPECT_NE(cornell.out.find("[ ] reflections: no opaque material with roughness <= 0.3"), std::string::npos)
        << cornell.out;
    const CliRun showcase = runCli("plan --scene builtin:showcase --json");
    ASSERT_EQ(showcase.exitCode, 0) << showcase.out;
    const nlohmann::json j = nlohmann::json::parse(showcase.out);
    ASSERT_EQ(j["passes"].size(), 9u);
    // Every pass but the path tracer (a workload, planned only on request).
    for (const auto& p : j["passes"]) EXPECT_EQ(p["planned"].get<bool>(), p["pass"] != "pathtrace") << p.dump();
    const CliRun narrowed = runCli("plan --scene builtin:cornell --effects ao,reflections");
    ASSERT_EQ(narrowed.exitCode, 0);
    EXPECT_NE(narrowed.out.find("note: reflections requested but not planned"), std::string::npos) << narrowed.out;
}

TEST(Cli, ShowcaseEffectsAndDdgiRender) {
    const fs::path out = freshDir("effects");
    const CliRun r =
        runCli("render --scene builtin:showcase --denoise none --gi ddgi --frames 2 --width 64 --height 36 --out " +
               out.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    EXPECT_TRUE(fs::exists(out / "frame_0001_ddgi.exr"));
    const rtlab::Image img = rtlab::readExr(out / "frame_0001.exr");
    for (const char* layer :
         {"R", "shadow.light0.V", "reflection.R", "ao.V", "gi.R", "translucency.R", "volume.inscatter.R"})
        EXPECT_TRUE(img.hasChannel(layer)) << layer;
    std::ifstream in(out / "stats.json");
    const nlohmann::json stats = nlohmann::json::parse(in);
    const auto& passes = stats["frames"][1]["passes"];
    for (const char* p : {"gbuffer", "shadows", "reflections", "ao", "gi", "translucency", "volumes"}) {
        EXPECT_GT(passes[p]["rays"].get<std::uint64_t>(), 0u) << p;
        EXPECT_GT(passes[p]["bytesAllocated"].get<std::uint64_t>(), 0u) << p;
    }
    EXPECT_GT(stats["frames"][1]["shaders"]["anyHit"].get<std::uint64_t>(), 0u);
    EXPECT_EQ(stats["frames"][1]["nonFiniteValuesRepaired"].get<int>(), 0);
    EXPECT_EQ(stats["plan"]["gi"], "ddgi");
    // The probe states sum to the probe count; only traced probes cost rays.
    const auto& probes = stats["frames"][1]["ddgi"]["probes"];
    const auto count = [&](const char* k) { return probes[k].get<std::uint64_t>(); };
    EXPECT_GT(count("active"), 0u);
    EXPECT_EQ(stats["frames"][1]["ddgi"]["rays"].get<std::uint64_t>(), count("traced") * 128u);
    EXPECT_LE(count("traced"), count("active") + count("relocating") + count("inside") + count("idle"));
}

// --denoise auto filters every effect's signal (SVGF per layer) and composes
// again: the 1-spp beauty gets closer to a 64-spp reference than the raw one.
TEST(Cli, DenoisedBeautyIsCloserToTheReference) {
    const fs::path raw = freshDir("dn_raw"), den = freshDir("dn_den"), ref = freshDir("dn_ref");
    const std::string common = "render --scene builtin:cornell --width 64 --height 48 --frames 2 ";
    ASSERT_EQ(runCli(common + "--denoise none --out " + raw.string()).exitCode, 0);
    ASSERT_EQ(runCli(common + "--denoise auto --out " + den.string()).exitCode, 0);
    ASSERT_EQ(runCli(common + "--denoise none --spp 64 --out " + ref.string()).exitCode, 0);
    const rtlab::Image r = rtlab::readExr(raw / "frame_0001.exr");
    const rtlab::Image d = rtlab::readExr(den / "frame_0001.exr");
    const rtlab::Image reference = rtlab::readExr(ref / "frame_0001.exr");
    EXPECT_TRUE(d.hasChannel("noisy.R"));
    EXPECT_TRUE(d.hasChannel("noisy.gi.R"));
    EXPECT_TRUE(d.hasChannel("noisy.shadow.light0.V"));
    // The noisy layers of the denoised run are the raw run's layers.
    const float* a = d.channel("noisy.gi.G");
    const float* b = r.channel("gi.G");
    for (std::size_t i = 0; i < r.pixelCount(); ++i) ASSERT_EQ(a[i], b[i]) << i;
    // Beauty error against the reference (relMSE over R, G, B).
    const auto relMse = [&](const rtlab::Image& img) {
        double sum = 0.0;
        for (const char* c : {"R", "G", "B"}) {
            const float* x = img.channel(c);
            const float* y = reference.channel(c);
            for (std::size_t i = 0; i < img.pixelCount(); ++i)
                sum += double(x[i] - y[i]) * double(x[i] - y[i]) / (double(y[i]) * double(y[i]) + 1e-2);
        }
        return sum / (3.0 * double(img.pixelCount()));
    };
    const double rawError = relMse(r), denoisedError = relMse(d);
    std::printf("[ denoise  ] cornell 1 spp relMSE: raw %.5f, denoised %.5f\n", rawError, denoisedError);
    EXPECT_LT(denoisedError, 0.5 * rawError);
    std::ifstream in(den / "stats.json");
    const nlohmann::json stats = nlohmann::json::parse(in);
    EXPECT_EQ(stats["settings"]["denoise"], "auto");
    EXPECT_GE(stats["frames"][1]["denoised"].size(), 3u);  // shadow.light0.V, ao.V, gi
}

TEST(Cli, ConvergeMeasuresRawAndDenoisedAgainstACachedReference) {
    const fs::path out = freshDir("converge"), cache = freshDir("converge_cache");
    const std::string args =
        "converge --scene builtin:cornell --effect ao --width 48 --height 32 --reference-spp 64 "
        "--max-spp 8 --denoise-max-spp 2 --frames 2 --out " +
        out.string() + " --cache " + cache.string();
    const CliRun first = runCli(args);
    ASSERT_EQ(first.exitCode, 0) << first.out;
    for (const char* f : {"converge.json", "converge.csv", "converge.png", "reference.png", "raw_1spp.png",
                          "ao_1spp.png", "flip_raw_1spp.png", "flip_ao_1spp.png", "ao_2frames.png"})
        EXPECT_TRUE(fs::exists(out / f)) << f;
    std::ifstream in(out / "converge.json");
    const nlohmann::json j = nlohmann::json::parse(in);
    EXPECT_FALSE(j["reference"]["cached"].get<bool>());
    // Raw error falls with samples; the AO stack beats raw 1 spp; every metric is finite.
    std::vector<double> raw;
    for (const auto& r : j["rows"]) {
        for (const char* k : {"ms", "relMse", "ssim", "flip"}) EXPECT_TRUE(std::isfinite(r[k].get<double>())) << k;
        EXPECT_GE(r["flip"].get<double>(), 0.0);
        EXPECT_LE(r["flip"].get<double>(), 1.0);
        // The worst 1 % of the 1536 pixels (15) hold at least their count's share.
        EXPECT_GE(r["worstPercentShare"].get<double>(), 15.0 / 1536.0) << r.dump();
        EXPECT_LE(r["worstPercentShare"].get<double>(), 1.0);
        if (r["method"] == "raw") raw.push_back(r["relMse"].get<double>());
    }
    ASSERT_EQ(raw.size(), 4u);  // 1, 2, 4, 8 spp
    for (std::size_t i = 1; i < raw.size(); ++i) EXPECT_LT(raw[i], raw[i - 1]);
    // converge.csv: one line per JSON row, the worst-1 % share in its last column.
    std::ifstream csv(out / "converge.csv");
    std::string header, line;
    std::getline(csv, header);
    EXPECT_EQ(header.substr(header.rfind(',') + 1), "worst_percent_share");
    std::size_t lines = 0;
    while (std::getline(csv, line)) {
        const double share = std::stod(line.substr(line.rfind(',') + 1));
        const double expected = j["rows"][lines]["worstPercentShare"].get<double>();
        EXPECT_NEAR(share, expected, 1e-5 * expected) << line;  // %.6g in the CSV
        ++lines;
    }
    EXPECT_EQ(lines, j["rows"].size());
    EXPECT_EQ(j["summary"]["stack"], "ao");
    EXPECT_GT(j["summary"]["relMseReduction"].get<double>(), 2.0);
    EXPECT_GT(j["summary"]["equalErrorSpeedup"].get<double>(), 0.0);
    // The second run reads the reference from the cache.
    const CliRun second = runCli(args);
    ASSERT_EQ(second.exitCode, 0) << second.out;
    EXPECT_NE(second.out.find("(cached)"), std::string::npos) << second.out;
}

TEST(Cli, ConvergeRejectsBadInputWithExitTwo) {
    const fs::path out = freshDir("converge_bad");
    for (const std::string& args : std::vector<std::string>{
             "converge --scene builtin:cornell --effect sparkles",
             "converge --scene builtin:cornell --effect reflections",
             "converge --scene " + (kAssimp / "IndexOutOfRange/IndexOutOfRange.gltf").string() + " --effect ao",
             std::string("converge --scene builtin:cornell")}) {
        const CliRun r = runCli(args + " --width 16 --height 16 --reference-spp 4 --out " + out.string() + " --cache " +
                                out.string());
        EXPECT_EQ(r.exitCode, 2) << args << "\n" << r.out;
        EXPECT_FALSE(fs::exists(out / "converge.json")) << args;
    }
}

TEST(Cli, ConvergeAcceptsSampleCountsThatAreNotPowersOfTwo) {
    // The denoisers run on the raw sample counts up to --denoise-max-spp
    // (raw: 1, 2, 4, 6; denoised: 1, 2), and a bad scene leaves no directories.
    const fs::path out = freshDir("converge_odd"), cache = freshDir("converge_odd_cache");
    const CliRun r = runCli(
        "converge --scene builtin:cornell --effect ao --width 24 --height 16 --reference-spp 8 "
        "--max-spp 6 --denoise-max-spp 3 --frames 3 --out " +
        out.string() + " --cache " + cache.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    std::ifstream in(out / "converge.json");
    const nlohmann::json j = nlohmann::json::parse(in);
    int raw = 0, denoised = 0;
    for (const auto& row : j["rows"]) {
        if (row["method"] == "raw") ++raw;
        if (row["method"] == "ao" && row["kind"] == "spp") ++denoised;
    }
    EXPECT_EQ(raw, 4);
    EXPECT_EQ(denoised, 2);
    const fs::path badOut = freshDir("converge_bad_scene");
    const CliRun bad = runCli("converge --scene builtin:nonesuch --effect ao --out " + badOut.string() + " --cache " +
                              (badOut / "cache").string());
    EXPECT_EQ(bad.exitCode, 2) << bad.out;
    EXPECT_FALSE(fs::exists(badOut));
}

TEST(Cli, CameraOptionReplacesTheScenesCamera) {
    // The LightWave polygon of assimp-testmodels lies in a plane x = const: the
    // default camera (from +Z) sees it edge-on; --camera looks at its face.
    const std::string obj = "/usr/share/assimp/models/OBJ/concave_polygon.obj";
    ASSERT_TRUE(fs::exists(obj)) << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    const fs::path out = freshDir("camera");
    const CliRun r = runCli("render --width 32 --height 24 --denoise none --scene " + obj +
                            " --camera 3,2.4,2.35,-1.146,2.4,2.35,0,1,0,40 --out " + out.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    const rtlab::Image img = rtlab::readExr(out / "frame_0000.exr");
    const float* albedo = img.channel("albedo.R");
    ASSERT_NE(albedo, nullptr);
    std::size_t covered = 0;
    for (int i = 0; i < img.width() * img.height(); ++i) covered += albedo[i] > 0.f;
    EXPECT_GT(covered, std::size_t(img.width() * img.height() / 10));  // the polygon, face on
    for (const char* bad : {"1,2,3", "0,0,0,0,0,0", "0,0,1,0,0,0,0,0,1", "0,0,1,0,0,0,0,1,0,200", "a,b,c,d,e,f"}) {
        const CliRun b = runCli("render --width 8 --height 8 --scene builtin:cornell --camera " + std::string(bad) +
                                " --out " + (out / "bad").string());
        EXPECT_EQ(b.exitCode, 2) << bad << "\n" << b.out;
        EXPECT_NE(b.out.find("--camera"), std::string::npos) << b.out;
    }
    // --camera interior: inside the Cornell box every pixel sees a wall.
    const CliRun inside = runCli(
        "render --width 16 --height 12 --effects gbuffer --denoise none --scene builtin:cornell "
        "--camera interior --out " +
        (out / "interior").string());
    ASSERT_EQ(inside.exitCode, 0) << inside.out;
    std::ifstream statsFile(out / "interior" / "stats.json");
    const nlohmann::json stats = nlohmann::json::parse(statsFile);
    EXPECT_EQ(stats["frames"][0]["rays"]["primary"]["hits"], 16 * 12);
}

// A load over a second says how long it took (one line; the threshold is
// RTLAB_LOAD_NOTICE_SECONDS, 0 here); a quick load says nothing.
TEST(Cli, ASlowLoadSaysHowLongItTook) {
    const CliRun slow = runCommand("RTLAB_LOAD_NOTICE_SECONDS=0 " + std::string(RTLAB_CLI) +
                                   " info --scene 'builtin:hairball?triangles=2000'");
    ASSERT_EQ(slow.exitCode, 0) << slow.out;
    EXPECT_NE(slow.out.find("rtlab: loaded builtin:hairball?triangles=2000 in "), std::string::npos) << slow.out;
    EXPECT_NE(slow.out.find(" s (2000 triangles)\n"), std::string::npos) << slow.out;
    // Below the threshold nothing is said (60 s: the default 1 s can pass on a loaded machine).
    const CliRun quick =
        runCommand("RTLAB_LOAD_NOTICE_SECONDS=60 " + std::string(RTLAB_CLI) + " info --scene builtin:cornell");
    ASSERT_EQ(quick.exitCode, 0) << quick.out;
    EXPECT_EQ(quick.out.find("rtlab: loaded"), std::string::npos) << quick.out;
    const CliRun failed =
        runCommand("RTLAB_LOAD_NOTICE_SECONDS=0 " + std::string(RTLAB_CLI) + " info --scene /nonexistent/file.obj");
    EXPECT_EQ(failed.exitCode, 2) << failed.out;
    EXPECT_EQ(std::count(failed.out.begin(), failed.out.end(), '\n'), 1) << failed.out;
}

// OpenVDB is loaded only for volumes (its module, docs/api.md): without the
// module a scene without volumes renders, while making or reading a grid is
// an internal error (exit 1) saying where the module was looked for, never
// blamed on the file.
TEST(Cli, OpenVdbIsLoadedOnlyForVolumes) {
    const std::string withoutModule = "RTLAB_OPENVDB_MODULE=/nonexistent/librtlab_openvdb.so " + std::string(RTLAB_CLI);
    const fs::path out = freshDir("without_openvdb");
    const CliRun cornell =
        runCommand(withoutModule + " render --scene builtin:cornell --width 16 --height 16 --out " + out.string());
    EXPECT_EQ(cornell.exitCode, 0) << cornell.out;
    const CliRun fog = runCommand(withoutModule + " info --scene builtin:showcase");  // a procedural fog
    EXPECT_EQ(fog.exitCode, 1) << fog.out;
    EXPECT_NE(fog.out.find("OpenVDB module librtlab_openvdb.so, which was not found or could not be loaded (tried "
                           "/nonexistent/librtlab_openvdb.so (absent)); set RTLAB_OPENVDB_MODULE"),
              std::string::npos)
        << fog.out;
    // A .vdb file: its separate-process check fails the same way.
    const fs::path vdb = fs::path(RTLAB_SOURCE_DIR) / "tests" / "regression_inputs" / "vdb" / "slow_reject_1.vdb";
    const fs::path scene = out / "volume.json";
    std::ofstream(scene) << R"({"gltf": [], "volumes": [{"file": ")" << vdb.string() << R"("}]})";
    const CliRun file = runCommand(withoutModule + " info --scene " + scene.string());
    EXPECT_EQ(file.exitCode, 1) << file.out;
    EXPECT_NE(file.out.find("the separate-process check of " + vdb.string() + " failed: volumes need"),
              std::string::npos)
        << file.out;
    EXPECT_EQ(file.out.find("corrupt"), std::string::npos) << file.out;
    // With the module, the same file is the file's fault.
    const CliRun corrupt = runCli("info --scene " + scene.string());
    EXPECT_EQ(corrupt.exitCode, 2) << corrupt.out;
}

// docs/scene-format.md's table of every OBJ, PLY and FBX file of
// assimp-testmodels holds row by row: rtlab info's outcome (triangles, an
// empty scene with its warning, or exit 2 with one line) and assimp info's
// verdict (assimp-utils); and the table lists every such file.
TEST(Cli, TheAssimpTestModelTableHolds) {
    const fs::path models = "/usr/share/assimp/models";
    ASSERT_TRUE(fs::exists(models / "OBJ")) << "assimp-testmodels not installed (scripts/install-deps.sh installs it)";
    ASSERT_TRUE(fs::exists("/usr/bin/assimp")) << "assimp-utils not installed (scripts/install-deps.sh installs it)";
    std::ifstream doc(fs::path(RTLAB_SOURCE_DIR) / "docs" / "scene-format.md");
    std::string line;
    bool inTable = false;
    std::map<std::string, std::pair<std::string, std::string>> table;  // file -> (assimp, rtlab)
    const auto trim = [](std::string s) {
        s.erase(0, s.find_first_not_of(' '));
        s.erase(s.find_last_not_of(' ') + 1);
        return s;
    };
    while (std::getline(doc, line)) {
        if (line.find("<!-- assimp-testmodels table") == 0) inTable = true;
        else if (line.find("<!-- end of assimp-testmodels table") == 0) inTable = false;
        else if (inTable && line.rfind("| `", 0) == 0) {
            std::vector<std::string> cells;
            std::stringstream row(line.substr(1));
            std::string cell;
            while (std::getline(row, cell, '|')) cells.push_back(trim(cell));
            ASSERT_GE(cells.size(), 4u) << line;
            table[cells[0].substr(1, cells[0].size() - 2)] = {cells[2], cells[3]};
        }
    }
    // Step: the table lists every OBJ, PLY and FBX file of OBJ/, PLY/, FBX/ and invalid/.
    std::set<std::string> files;
    for (const auto& e : fs::recursive_directory_iterator(models)) {
        std::string ext = e.path().extension().string();
        std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
        const std::string rel = fs::relative(e.path(), models).string();
        const std::string top = rel.substr(0, rel.find('/'));
        if (e.is_regular_file() && (ext == ".obj" || ext == ".ply" || ext == ".fbx") &&
            (top == "OBJ" || top == "PLY" || top == "FBX" || top == "invalid"))
            files.insert(rel);
    }
    std::set<std::string> listed;
    for (const auto& [file, outcome] : table) listed.insert(file);
    EXPECT_EQ(listed, files);
    ASSERT_GE(table.size(), 50u);
    // Step: each row, against rtlab info and assimp info.
    for (const auto& [file, outcome] : table) {
        const auto& [assimpVerdict, rtlabOutcome] = outcome;
        const std::string path = (models / file).string();
        const CliRun r = runCli("info --scene '" + path + "'");
        if (rtlabOutcome.rfind("renders: ", 0) == 0) {
            EXPECT_EQ(r.exitCode, 0) << file << "\n" << r.out;
            const std::string count = rtlabOutcome.substr(9, rtlabOutcome.find(' ', 9) - 9);
            EXPECT_NE(r.out.find("triangles: " + count + " unique"), std::string::npos) << file << "\n" << r.out;
        } else if (rtlabOutcome.rfind("empty scene: ", 0) == 0) {
            EXPECT_EQ(r.exitCode, 0) << file << "\n" << r.out;
            EXPECT_NE(r.out.find("triangles: 0 unique"), std::string::npos) << file << "\n" << r.out;
            EXPECT_NE(r.out.find(rtlabOutcome.substr(13)), std::string::npos) << file << "\n" << r.out;
        } else {
            ASSERT_EQ(rtlabOutcome.rfind("exit 2: ", 0), 0u) << file << ": " << rtlabOutcome;
            EXPECT_EQ(r.exitCode, 2) << file << "\n" << r.out;
            EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << file << "\n" << r.out;
            EXPECT_NE(r.out.find(rtlabOutcome.substr(8)), std::string::npos) << file << "\n" << r.out;
            EXPECT_NE(r.out.find(fs::path(file).filename().string()), std::string::npos) << file << "\n" << r.out;
        }
        const CliRun a = runCommand("assimp info '" + path + "'");
        if (assimpVerdict == "loads") {
            EXPECT_EQ(a.exitCode, 0) << file << ": assimp info\n" << a.out.substr(0, 2000);
        } else {
            ASSERT_EQ(assimpVerdict.rfind("rejects: ", 0), 0u) << file << ": " << assimpVerdict;
            EXPECT_NE(a.exitCode, 0) << file << ": assimp info";
            EXPECT_NE(a.out.find(assimpVerdict.substr(9)), std::string::npos) << file << "\n" << a.out.substr(0, 2000);
        }
    }
}

// An alpha mask is the geometry's shape: --effects gbuffer on showcase still
// runs the foliage's any-hit alpha test on both back ends (rays pass its
// holes), and only --opaque closes them; rtlab plan says which.
TEST(Cli, AlphaMasksAreGeometryWhateverTheEffects) {
    for (const std::string backend : {"embree", "rtcore"}) {
        SCOPED_TRACE(backend);
        const fs::path masked = freshDir("alpha_masked_" + backend), opaque = freshDir("alpha_opaque_" + backend);
        const std::string common =
            "render --scene builtin:showcase --effects gbuffer --width 64 --height 36 "
            "--denoise none --backend " +
            backend;
        ASSERT_EQ(runCli(common + " --out " + masked.string()).exitCode, 0);
        ASSERT_EQ(runCli(common + " --opaque --out " + opaque.string()).exitCode, 0);
        const auto anyHits = [](const fs::path& dir) {
            std::ifstream in(dir / "stats.json");
            return nlohmann::json::parse(in)["frames"][0]["shaders"]["anyHit"].get<long long>();
        };
        EXPECT_GT(anyHits(masked), 0);
        EXPECT_EQ(anyHits(opaque), 0);
        // The holes: some pixels see another surface through the foliage.
        const rtlab::Image a = rtlab::readExr(masked / "frame_0000.exr"), b = rtlab::readExr(opaque / "frame_0000.exr");
        const float *meshA = a.channel("id.mesh"), *meshB = b.channel("id.mesh");
        ASSERT_NE(meshA, nullptr);
        ASSERT_NE(meshB, nullptr);
        int differing = 0;
        for (int i = 0; i < a.width() * a.height(); ++i) differing += meshA[i] != meshB[i];
        EXPECT_GT(differing, 0);
    }
    const CliRun plan = runCli("plan --scene builtin:showcase --effects gbuffer");
    ASSERT_EQ(plan.exitCode, 0) << plan.out;
    EXPECT_NE(plan.out.find("[x] alpha: "), std::string::npos) << plan.out;
    const CliRun closed = runCli("plan --scene builtin:showcase --effects gbuffer --opaque");
    ASSERT_EQ(closed.exitCode, 0) << closed.out;
    EXPECT_NE(closed.out.find("[ ] alpha: --opaque"), std::string::npos) << closed.out;
}

// The PNG preview shows what was asked for: --effects ao (no light in the
// beauty) writes the AO visibility, says so on stderr and in stats.json; the
// default effects write the beauty.
TEST(Cli, PreviewShowsTheRequestedSignalWhenTheBeautyHasNoLight) {
    const fs::path ao = freshDir("preview_ao"), beauty = freshDir("preview_beauty");
    const CliRun r = runCli("render --scene builtin:cornell --effects ao --width 32 --height 24 --denoise none --out " +
                            ao.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    EXPECT_NE(r.out.find("frame_0000.png shows ao.V (the AO visibility)"), std::string::npos) << r.out;
    std::ifstream in(ao / "stats.json");
    EXPECT_EQ(nlohmann::json::parse(in)["frames"][0]["preview"], "ao.V");
    // The PNG is the AO layer as grey: not black, and equal to ao.V where it is 0 or 1.
    const rtlab::Image frame = rtlab::readExr(ao / "frame_0000.exr");
    const float* v = frame.channel("ao.V");
    ASSERT_NE(v, nullptr);
    float brightest = 0.f;
    for (std::size_t p = 0; p < frame.pixelCount(); ++p) brightest = std::max(brightest, v[p]);
    EXPECT_GT(brightest, 0.5f);
    // The PNG: grey (R = G = B) and bright where ao.V is (sRGB-encoded, so compared by order).
    int w = 0, h = 0, channels = 0;
    unsigned char* png = stbi_load((ao / "frame_0000.png").c_str(), &w, &h, &channels, 3);
    ASSERT_NE(png, nullptr);
    ASSERT_EQ(std::size_t(w) * std::size_t(h), frame.pixelCount());
    int grey = 0, agrees = 0, pairs = 0;
    for (std::size_t p = 0; p < frame.pixelCount(); ++p) {
        grey += png[3 * p] == png[3 * p + 1] && png[3 * p + 1] == png[3 * p + 2];
        if (p > 0 && std::abs(v[p] - v[p - 1]) > 0.05f) {
            ++pairs;
            agrees += (v[p] > v[p - 1]) == (png[3 * p] > png[3 * (p - 1)]);
        }
    }
    stbi_image_free(png);
    EXPECT_EQ(grey, int(frame.pixelCount()));
    EXPECT_GT(pairs, 10);
    EXPECT_EQ(agrees, pairs);
    const CliRun lit =
        runCli("render --scene builtin:cornell --width 32 --height 24 --denoise none --out " + beauty.string());
    ASSERT_EQ(lit.exitCode, 0) << lit.out;
    EXPECT_EQ(lit.out.find(".png shows"), std::string::npos) << lit.out;
    std::ifstream litStats(beauty / "stats.json");
    EXPECT_EQ(nlohmann::json::parse(litStats)["frames"][0]["preview"], "beauty");
}
