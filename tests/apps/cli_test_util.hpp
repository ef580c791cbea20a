#pragma once
// Helpers for the end-to-end tests of the rtlab executable (RTLAB_CLI).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <sys/wait.h>

#include "../temp_dir.hpp"

namespace rtlab::test {

namespace fs = std::filesystem;

struct CliRun {
    int exitCode = -1;
    std::string out;  // stdout + stderr
};

// Runs a shell command; stdout + stderr and the exit code.
inline CliRun runCommand(const std::string& command) {
    CliRun r;
    FILE* pipe = popen((command + " 2>&1").c_str(), "r");
    if (!pipe) return r;
    std::array<char, 4096> buf{};
    while (fgets(buf.data(), buf.size(), pipe)) r.out += buf.data();
    const int status = pclose(pipe);
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return r;
}

// The rtlab executable with `args`.
inline CliRun runCli(const std::string& args) { return runCommand(std::string(RTLAB_CLI) + " " + args); }

// A directory of this test process, removed at exit (temp_dir.hpp).
inline fs::path freshDir(const std::string& name) { return rtlab::test::freshTempDir("cli_" + name); }

// DIR/stats.json without its "timing" and "measured" entries (everything
// else is deterministic).
inline nlohmann::json statsWithoutTiming(const fs::path& dir) {
    std::ifstream in(dir / "stats.json");
    nlohmann::json j = nlohmann::json::parse(in);
    j.erase("timing");
    for (auto& f : j["frames"]) {
        f.erase("timing");
        f.erase("measured");
    }
    return j;
}

// Renders `args` with --threads 1 and --threads 2 into two fresh directories
// (named after `name`); the caller asserts on what came out.
struct ThreadCountRuns {
    CliRun one, two;
    CliRun compare;                     // `rtlab compare` of the two runs' `frame`
    nlohmann::json statsOne, statsTwo;  // stats.json without timing (statsWithoutTiming)
    bool rendered() const { return one.exitCode == 0 && two.exitCode == 0; }
    bool framesIdentical() const {
        return compare.exitCode == 0 && compare.out.find("identical: true") != std::string::npos;
    }
};
inline ThreadCountRuns renderWithOneAndTwoThreads(const std::string& name, const std::string& args,
                                                  const std::string& frame = "frame_0000.exr") {
    ThreadCountRuns r;
    const fs::path a = freshDir(name + "_t1"), b = freshDir(name + "_t2");
    r.one = runCli(args + " --threads 1 --out " + a.string());
    r.two = runCli(args + " --threads 2 --out " + b.string());
    if (!r.rendered()) return r;
    r.compare = runCli("compare " + (a / frame).string() + " " + (b / frame).string());
    r.statsOne = statsWithoutTiming(a);
    r.statsTwo = statsWithoutTiming(b);
    return r;
}

}  // namespace rtlab::test
