// `rtlab render --effects pathtrace --max-depth D` end to end: per-vertex ray
// counts in stats.json, both back ends agree hit for hit (--verify) and give
// the same image, and one and two threads give bit-identical frames and stats.
#include "cli_test_util.hpp"

using namespace rtlab::test;

TEST(CliPathTrace, StatsCountRaysPerPathVertexAndThreadCountsAgree) {
    const ThreadCountRuns r =
        renderWithOneAndTwoThreads("pathtrace",
                                   "render --scene 'builtin:terrain?triangles=4000' --effects pathtrace --max-depth 2 "
                                   "--width 32 --height 24 --spp 2");
    ASSERT_TRUE(r.rendered()) << r.one.out << r.two.out;
    EXPECT_TRUE(r.framesIdentical()) << r.compare.out;
    EXPECT_EQ(r.statsOne, r.statsTwo);
    const nlohmann::json& f = r.statsOne["frames"][0];
    ASSERT_TRUE(f.contains("pathtrace")) << f.dump(1);
    EXPECT_EQ(f["pathtrace"]["maxDepth"], 2);
    const nlohmann::json& v = f["pathtrace"]["vertices"];
    ASSERT_EQ(v.size(), 3u);
    EXPECT_EQ(v[0]["bounceRays"], 0);
    long long bounces = 0;
    for (int d = 1; d <= 2; ++d) {
        EXPECT_GT(v[d]["bounceRays"].get<long long>(), 0) << d;
        EXPECT_LE(v[d]["bounceHits"].get<long long>(), v[d]["bounceRays"].get<long long>());
        bounces += v[d]["bounceRays"].get<long long>();
    }
    EXPECT_EQ(f["rays"]["pathBounce"]["traced"].get<long long>(), bounces);
    EXPECT_GT(f["rays"]["shadow"]["traced"].get<long long>(), 0);  // next-event rays under the terrain's sun
    EXPECT_EQ(f["passes"]["pathtrace"]["planned"], true);
    EXPECT_EQ(f["passes"]["ao"]["planned"], false);
}

TEST(CliPathTrace, RtCoreTracesTheSameHitsAndImageAsEmbree) {
    const fs::path a = freshDir("pathtrace_embree"), b = freshDir("pathtrace_rtcore");
    const std::string common =
        "render --scene builtin:cornell --effects pathtrace --max-depth 3 --width 24 --height 24";
    const CliRun embree = runCli(common + " --out " + a.string());
    ASSERT_EQ(embree.exitCode, 0) << embree.out;
    const CliRun rtcore = runCli(common + " --backend rtcore --verify --out " + b.string());
    ASSERT_EQ(rtcore.exitCode, 0) << rtcore.out;
    const nlohmann::json s = statsWithoutTiming(b);
    const nlohmann::json& f = s["frames"][0];
    EXPECT_GT(f["rays"]["pathBounce"]["traced"].get<long long>(), 0);
    EXPECT_EQ(f["rtcore"]["verify"]["mismatches"], 0);
    EXPECT_EQ(f["rtcore"]["verify"]["rays"].get<long long>(), f["rays"]["pathBounce"]["traced"].get<long long>() +
                                                                  f["rays"]["shadow"]["traced"].get<long long>() +
                                                                  f["rays"]["primary"]["traced"].get<long long>());
    const CliRun compare = runCli("compare " + (a / "frame_0000.exr").string() + " " + (b / "frame_0000.exr").string());
    EXPECT_NE(compare.out.find("identical: true"), std::string::npos) << compare.out;
}

TEST(CliPathTrace, MaxDepthOutOfRangeExitsTwo) {
    const CliRun r = runCli("render --scene builtin:cornell --effects pathtrace --max-depth 65 --out " +
                            freshDir("pathtrace_bad").string());
    EXPECT_EQ(r.exitCode, 2) << r.out;
    EXPECT_NE(r.out.find("--max-depth"), std::string::npos) << r.out;
}
