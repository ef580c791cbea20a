// End-to-end: the scalable builtin scenes (terrain, forest, hairball, slivers) through
// the rtlab executable: parameter errors, `rtlab info`, thread-count determinism.
#include "cli_test_util.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace rtlab::test;

TEST(CliScalableScenes, ParameterErrorsExitTwoWithOneLineNamingTheParameter) {
    struct Case {
        std::string scene, mentions;
    };
    const std::vector<Case> cases = {
        {"builtin:terrain?tris=5000", "unknown parameter 'tris' (accepted: triangles, seed)"},
        {"builtin:terrain?triangles=lots", "parameter 'triangles' has value 'lots'"},
        {"builtin:terrain?triangles=-5", "parameter 'triangles' has value '-5'"},
        {"builtin:terrain?triangles=999", "parameter 'triangles' is 999, out of range (1000 to 10000000)"},
        {"builtin:hairball?triangles=2e7", "out of range (1000 to 10000000)"},
        {"builtin:forest?instances=0", "parameter 'instances' is 0, out of range (1 to 1000000)"},
        {"builtin:forest?instances=10&instances=20", "parameter 'instances' given twice"},
        {"builtin:forest?seed", "expected key=value, got 'seed'"},
        {"builtin:slivers?seed=99999999999", "parameter 'seed' has value '99999999999'"},
        {"builtin:showcase?seed=1", "unknown parameter 'seed' (builtin:showcase takes no parameters)"},
        {"builtin:cornell?triangles=1000", "unknown parameter 'triangles' (builtin:cornell takes no parameters)"},
        {"builtin:nope?triangles=1000",
         "unknown builtin scene (available: showcase, cornell, terrain, forest, hairball, slivers)"},
    };
    for (const Case& c : cases)
        for (const std::string command : {"info", "plan", "render --width 8 --height 8 --out /tmp/rtlab_cli_never"}) {
            const CliRun r = runCli(command + " --scene '" + c.scene + "'");
            EXPECT_EQ(r.exitCode, 2) << command << " " << c.scene << "\n" << r.out;
            EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << c.scene << "\n" << r.out;
            EXPECT_EQ(r.out.rfind("rtlab: " + c.scene + ": ", 0), 0u) << r.out;  // names the source
            EXPECT_NE(r.out.find(c.mentions), std::string::npos) << c.scene << "\n" << r.out;
        }
}

TEST(CliScalableScenes, InfoShowsParametersAndUniqueAndInstancedTriangles) {
    // 1250 = 2 x 25^2 is a square grid; 1000 is not, 968 = 2 x 22^2 is the nearest.
    const CliRun exact = runCli("info --scene 'builtin:terrain?triangles=1250'");
    ASSERT_EQ(exact.exitCode, 0) << exact.out;
    EXPECT_NE(exact.out.find("parameters: triangles=1250 seed=0\n"), std::string::npos) << exact.out;
    EXPECT_NE(exact.out.find("triangles: 1250 unique, 1250 instanced"), std::string::npos) << exact.out;
    const CliRun nearest = runCli("info --scene 'builtin:terrain?seed=7&triangles=1e3'");
    ASSERT_EQ(nearest.exitCode, 0) << nearest.out;
    EXPECT_NE(nearest.out.find("parameters: triangles=1000 seed=7\n"), std::string::npos) << nearest.out;
    EXPECT_NE(nearest.out.find("generated: 22 x 22 quad height field, 968 unique triangles"), std::string::npos)
        << nearest.out;
    EXPECT_NE(nearest.out.find("triangles: 968 unique, 968 instanced"), std::string::npos) << nearest.out;

    const CliRun hair = runCli("info --scene 'builtin:hairball?triangles=2000'");
    ASSERT_EQ(hair.exitCode, 0) << hair.out;
    EXPECT_NE(hair.out.find("triangles: 2000 unique, 2000 instanced"), std::string::npos) << hair.out;
    EXPECT_NE(hair.out.find("generated: 2000 triangles in 125 curly strands"), std::string::npos) << hair.out;
    const CliRun slivers = runCli("info --scene 'builtin:slivers?triangles=2000'");
    ASSERT_EQ(slivers.exitCode, 0) << slivers.out;
    EXPECT_NE(slivers.out.find("generated: 2000 slivers"), std::string::npos) << slivers.out;

    // The forest: one ground plus 40 hashed instances of four meshes, so more
    // instanced than unique triangles.
    const CliRun forest = runCli("info --scene 'builtin:forest?instances=40'");
    ASSERT_EQ(forest.exitCode, 0) << forest.out;
    EXPECT_NE(forest.out.find("parameters: instances=40 seed=0\n"), std::string::npos) << forest.out;
    EXPECT_NE(forest.out.find("instances: 41\n"), std::string::npos) << forest.out;
    EXPECT_NE(forest.out.find("meshes: 5 "), std::string::npos) << forest.out;
    unsigned long long unique = 0, instanced = 0;
    const std::size_t at = forest.out.find("triangles: ");
    ASSERT_NE(at, std::string::npos);
    ASSERT_EQ(std::sscanf(forest.out.c_str() + at, "triangles: %llu unique, %llu instanced", &unique, &instanced), 2);
    EXPECT_GT(instanced, unique);
}

TEST(CliScalableScenes, GbufferFramesAreBitIdenticalOnOneAndTwoThreads) {
    for (const std::string scene : {"builtin:terrain?triangles=4000&seed=3", "builtin:forest?instances=60",
                                    "builtin:hairball?triangles=3000", "builtin:slivers?triangles=3000"}) {
        SCOPED_TRACE(scene);
        const ThreadCountRuns r = renderWithOneAndTwoThreads(
            "scalable", "render --scene '" + scene + "' --effects gbuffer --width 32 --height 24");
        ASSERT_TRUE(r.rendered()) << r.one.out << r.two.out;
        EXPECT_TRUE(r.framesIdentical()) << r.compare.out;
        EXPECT_EQ(r.statsOne, r.statsTwo);
        // The camera sees the content: primary rays hit something.
        EXPECT_GT(r.statsOne["frames"][0]["rays"]["primary"]["hits"].get<long long>(), 0);
    }
}

// stats.json reports the acceleration structures' memory per unique triangle:
// rtlab's clusters and the model's layout (deterministic) and Embree's bytes
// (measured). Cluster bytes lie between one and four triangles per cluster.
TEST(CliScalableScenes, StatsReportAccelerationStructureBytesPerTriangle) {
    const fs::path dir = freshDir("accel_memory");
    const CliRun r = runCli(
        "render --scene 'builtin:terrain?triangles=4000' --backend rtcore --effects gbuffer "
        "--denoise none --width 16 --height 12 --out " +
        dir.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    std::ifstream in(dir / "stats.json");
    const nlohmann::json frame = nlohmann::json::parse(in)["frames"][0];
    const nlohmann::json& m = frame["accelMemory"];
    const double triangles = m["uniqueTriangles"].get<double>();
    EXPECT_NEAR(triangles, 4000.0, 200.0);
    const double clusterBytes = m["watertightClusterBytes"].get<double>();
    EXPECT_GE(clusterBytes, triangles / 4.0 * 176.0);
    EXPECT_LE(clusterBytes, triangles * 176.0);
    EXPECT_DOUBLE_EQ(m["watertightClusterBytesPerTriangle"].get<double>(), clusterBytes / triangles);
    EXPECT_GT(m["rtcoreModelBytes"].get<double>(), 0.0);
    EXPECT_GT(frame["measured"]["embreeBytes"].get<double>(), 0.0);
}
