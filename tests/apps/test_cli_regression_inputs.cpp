// The regression corpus (tests/regression_inputs/TARGET/, README.md there):
// inputs that once crashed, hung or exhausted memory, found by the fuzz
// targets (fuzz/) or by hand. Each is replayed through the normal rtlab, the
// way its fuzz target reads it (a scene format rendered at 8x8, a .vdb named
// by a scene .json, a .mtl beside a fixed OBJ, a ray trace replayed on both
// back ends, a study swept, an RT-core configuration rendered with, an EXR
// compared): a file named loads_* must succeed, any other must exit 2 with one
// line naming the file (a replayed trace may also exit 1, its hits differing). `make test-asan` replays them under ASan + UBSan too.
#include "cli_test_util.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace rtlab::test {
namespace {

const fs::path kCorpus = fs::path(RTLAB_SOURCE_DIR) / "tests" / "regression_inputs";

void writeText(const fs::path& path, const std::string& text) { std::ofstream(path, std::ios::binary) << text; }

// The commands that read `input` as fuzz target `target` does; `work` is a scratch directory.
std::vector<std::string> commandsFor(const std::string& target, const fs::path& input, const fs::path& work) {
    const std::string out = " --out '" + (work / "out").string() + "'";
    const std::string render = "render --width 8 --height 8 --denoise none --threads 1" + out + " --scene ";
    const auto renderOf = [&](const fs::path& scene) {  // the render command of a scene file, quoted
        std::string command = render;
        command += '\'';
        command += scene.string();
        command += '\'';
        return command;
    };
    if (target == "vdb") {
        fs::copy_file(input, work / input.filename(), fs::copy_options::overwrite_existing);
        writeText(work / "scene.json", R"({"gltf": [], "volumes": [{"file": ")" + input.filename().string() +
                                           R"(", "densityScale": 0.5}], "camera": {"position": [0, 1, 6], )"
                                           R"("lookAt": [0, 0, 0], "yfov": 0.8}})");
        return {renderOf(work / "scene.json")};
    }
    if (target == "mtl") {
        fs::copy_file(input, work / "case.mtl", fs::copy_options::overwrite_existing);
        writeText(work / "case.obj",
                  "mtllib case.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                  "usemtl material\nf 1/1 2/2 3/3\nusemtl other\nf 1/1 3/3 4/4\n");
        return {renderOf(work / "case.obj")};
    }
    if (target == "scene_json") {  // beside the model its fuzz target puts there
        fs::copy_file(input, work / "case.json", fs::copy_options::overwrite_existing);
        fs::copy_file(fs::path(RTLAB_SOURCE_DIR) / "fuzz" / "scene_json_model.gltf", work / "model.gltf",
                      fs::copy_options::overwrite_existing);
        return {renderOf(work / "case.json")};
    }
    const std::string file = "'" + input.string() + "'";
    if (target == "ray_trace")
        return {"replay --scene builtin:cornell --threads 1 --rays " + file + out,
                "replay --scene builtin:cornell --backend rtcore --threads 1 --rays " + file + out};
    if (target == "study") return {"sweep " + file + out};
    if (target == "rtcore_config")
        return {
            "render --scene builtin:cornell --backend rtcore --effects gbuffer --width 4 --height 4 --denoise none "
            "--threads 1 --rtcore-config " +
            file + out};
    if (target == "exr") return {"compare " + file + " " + file};
    return {render + file};  // gltf, glb, obj, ply, fbx
}

TEST(Cli, RegressionInputsExitTwoWithOneLineOrLoad) {
    const std::vector<std::string> targets = {"gltf", "glb", "scene_json", "vdb",   "obj",           "mtl",
                                              "ply",  "fbx", "ray_trace",  "study", "rtcore_config", "exr"};
    std::map<std::string, int> replayed;
    for (const auto& folder : fs::directory_iterator(kCorpus)) {
        if (!folder.is_directory()) continue;
        const std::string target = folder.path().filename().string();
        ASSERT_NE(std::find(targets.begin(), targets.end(), target), targets.end())
            << folder.path() << " is not a fuzz target's folder";
        for (const auto& e : fs::directory_iterator(folder.path())) {
            const fs::path work = freshDir("regression_" + target + "_" + e.path().filename().string());
            fs::create_directories(work);
            const bool loads = e.path().filename().string().rfind("loads_", 0) == 0;
            for (const std::string& command : commandsFor(target, e.path(), work)) {
                const CliRun r = runCli(command);
                ++replayed[target];
                if (loads) {
                    EXPECT_EQ(r.exitCode, 0) << command << "\n" << r.out;
                    continue;
                }
                // A replay whose hits differ from the recording exits 1 with its one summary line
                // (docs/ray-trace-format.md): an answer about the file, not a failure.
                if (target == "ray_trace" && r.exitCode == 1) {
                    EXPECT_NE(r.out.find("hit(s) differ from the recording"), std::string::npos) << r.out;
                    EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << command << "\n" << r.out;
                    continue;
                }
                EXPECT_EQ(r.exitCode, 2) << command << "\n" << r.out;
                EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << command << "\n" << r.out;
                const std::string named = target == "mtl" ? "case." : e.path().filename().string();
                EXPECT_NE(r.out.find(named), std::string::npos) << command << "\n" << r.out;
            }
        }
    }
    std::size_t total = 0;
    for (const auto& [target, n] : replayed) total += n;
    EXPECT_GE(total, 6u);
}

}  // namespace
}  // namespace rtlab::test
