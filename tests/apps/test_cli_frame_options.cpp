// One set of frame options for every command: rtlab converge renders the
// frame rtlab render renders for the same options (the translucency layer at
// a non-default --max-translucency-depth, which converge once ignored).
#include "cli_test_util.hpp"

#include <rtlab/core/image.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>

namespace rtlab::test {
namespace {

const std::string kSize = " --scene builtin:showcase --width 48 --height 27 --seed 3";

// The translucency term (transmission x translucency) of render's frame 0.
std::vector<vec3> renderedTranslucency(const fs::path& dir, int depth) {
    const CliRun r = runCli("render" + kSize + " --effects translucency --denoise none --max-translucency-depth " +
                            std::to_string(depth) + " --out " + dir.string());
    EXPECT_EQ(r.exitCode, 0) << r.out;
    return shaders::effectContribution(readExr(dir / "frame_0000.exr"), "translucency");
}

TEST(CliFrameOptions, ConvergeRendersTheFrameRenderRenders) {
    const fs::path dir = freshDir("frame_options");
    const std::vector<vec3> depth2 = renderedTranslucency(dir / "render2", 2);
    const std::vector<vec3> depth8 = renderedTranslucency(dir / "render8", 8);
    ASSERT_NE(depth2, depth8) << "the showcase's glass must need more than 2 events, or this test shows nothing";

    const CliRun c = runCli("converge" + kSize +
                            " --effect translucency --max-translucency-depth 2 "
                            "--reference-spp 2 --max-spp 1 --denoise-max-spp 1 --frames 1 --cache " +
                            (dir / "cache").string() + " --out " + (dir / "converge").string());
    ASSERT_EQ(c.exitCode, 0) << c.out;
    // converge's raw 1-spp image is frame 0 at 1 spp with the run's seed: render's frame, bit for bit.
    const Image raw = readExr(dir / "converge" / "raw_1spp.exr");
    EXPECT_EQ(raw.rgbLayer(""), depth2);
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "converge" / "converge.json"));
    EXPECT_EQ(j["settings"]["maxTranslucencyDepth"], 2);
}

TEST(CliFrameOptions, ConvergeRefusesRenderOnlyOptions) {
    // --spp and --max-depth shape render's frames, not converge's (which sweeps spp itself).
    for (const char* option : {"--spp 2", "--max-depth 2", "--backend rtcore"}) {
        const CliRun r = runCli(std::string("converge --effect ao ") + option);
        EXPECT_EQ(r.exitCode, 2) << option << ": " << r.out;
    }
}

TEST(CliFrameOptions, PlanAndReplayRequireAScene) {
    for (const char* command : {"plan", "replay --rays /nonexistent"}) {
        const CliRun r = runCli(command);
        EXPECT_EQ(r.exitCode, 2) << command << ": " << r.out;
        EXPECT_NE(r.out.find("--scene is required"), std::string::npos) << command << ": " << r.out;
    }
}

}  // namespace
}  // namespace rtlab::test
