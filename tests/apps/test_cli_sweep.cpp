// End-to-end: rtlab sweep and rtlab report (docs/studies.md): the minimal
// study of issue 15, resume after SIGKILL / SIGINT, --jobs and MPI give the
// same rows, a changed study is refused, bad studies exit 2 naming the key.
#include "cli_test_util.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;
using namespace rtlab::test;
using nlohmann::json;

namespace {

// The minimal study of issue 15, as written there, on the single-core preset
// (the default then; a point's node cache is the only one on the GPU).
const char* kIssueStudy = R"({"workloads": ["builtin:cornell"],
 "render": {"width": 64, "height": 64, "frames": 1, "effects": "gbuffer", "backend": "rtcore", "rtcoreConfig": "single-core"},
 "grid": {"cache.sizeBytes": [4096, 32768], "traversal.units": [1, 2]}})";

// A small study: 2 workloads x 3 cache sizes = 6 points, 32x32 gbuffer.
const char* kSmallStudy = R"({"workloads": ["builtin:cornell", "builtin:terrain?triangles=2000"],
 "render": {"width": 32, "height": 32, "effects": "gbuffer", "rtcoreConfig": "single-core"},
 "grid": {"cache.sizeBytes": [2048, 8192, 32768]}})";

fs::path writeStudy(const std::string& name, const std::string& text) {
    const fs::path dir = freshDir("study_" + name);
    fs::create_directories(dir);
    std::ofstream(dir / "study.json") << text;
    return dir / "study.json";
}

std::string readText(const fs::path& path) {
    std::ifstream in(path);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

std::vector<json> rows(const fs::path& dir) {
    std::vector<json> out;
    std::ifstream in(dir / "results.jsonl");
    std::string line;
    while (std::getline(in, line))
        if (!line.empty()) out.push_back(json::parse(line));
    return out;
}

// The rows without their timing fields (everything else is deterministic).
std::vector<json> rowsWithoutTiming(const fs::path& dir) {
    std::vector<json> out = rows(dir);
    for (json& r : out) r.erase("timing");
    return out;
}

std::size_t countResults(const fs::path& dir) {
    std::size_t n = 0;
    if (!fs::exists(dir / "points")) return 0;
    for (const auto& e : fs::directory_iterator(dir / "points")) n += fs::exists(e.path() / "result.json");
    return n;
}

// Starts `rtlab sweep STUDY --out DIR --jobs 1` in the background (output to LOG).
pid_t startSweep(const fs::path& study, const fs::path& out, const fs::path& log) {
    const pid_t pid = fork();
    if (pid == 0) {
        const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(fd, 1);
        dup2(fd, 2);
        execl(RTLAB_CLI, RTLAB_CLI, "sweep", study.c_str(), "--out", out.c_str(), "--jobs", "1", (char*)nullptr);
        _exit(127);
    }
    return pid;
}

// Runs a 10-point sweep, kills it with a signal once 2 points are complete,
// then reruns it and runs the same study once uninterrupted. Records what the
// test asserts on; asserts nothing itself.
struct KillAndResumeRun {
    bool started = false;
    bool killedBySignal = false;                       // the sweep was still running when killed
    std::string firstLog;                              // its stdout + stderr
    std::size_t kept = 0;                              // complete points right after the kill
    std::size_t keptLater = 0;                         // ... 1.5 s later (nothing of the killed sweep lives on)
    std::map<std::string, std::string> before, after;  // point -> result.json text, before / after the rerun
    CliRun again, once;                                // the rerun, the uninterrupted run
    std::vector<json> resumed, fresh;                  // their rows without timing
};

KillAndResumeRun killAndResume(const std::string& name, int sig) {
    KillAndResumeRun r;
    const fs::path study = writeStudy(name, R"({"workloads": ["builtin:cornell", "builtin:terrain?triangles=20000"],
 "render": {"width": 48, "height": 48, "frames": 2, "effects": "gbuffer"},
 "grid": {"cache.sizeBytes": [2048, 4096, 8192, 16384, 32768]}})");
    const fs::path out = freshDir(name + "_out");
    const pid_t pid = startSweep(study, out, study.parent_path() / "first.log");
    r.started = pid > 0;
    if (!r.started) return r;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (countResults(out) < 2 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    kill(pid, sig);
    int status = 0;
    waitpid(pid, &status, 0);
    r.killedBySignal = WIFSIGNALED(status);
    r.firstLog = readText(study.parent_path() / "first.log");
    r.kept = countResults(out);
    for (const auto& e : fs::directory_iterator(out / "points"))
        if (fs::exists(e.path() / "result.json")) r.before[e.path().filename()] = readText(e.path() / "result.json");
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));
    r.keptLater = countResults(out);

    r.again = runCli("sweep " + study.string() + " --out " + out.string() + " --jobs 2");
    for (const auto& [point, text] : r.before) r.after[point] = readText(out / "points" / point / "result.json");
    if (r.again.exitCode == 0) r.resumed = rowsWithoutTiming(out);
    const fs::path fresh = freshDir(name + "_fresh");
    r.once = runCli("sweep " + study.string() + " --out " + fresh.string() + " --jobs 2");
    if (r.once.exitCode == 0) r.fresh = rowsWithoutTiming(fresh);
    return r;
}

class SweepKillAndResume : public ::testing::TestWithParam<int> {};

}  // namespace

TEST(Sweep, IssueMinimalStudyWritesFourRowsAndStats) {
    const fs::path study = writeStudy("issue", kIssueStudy);
    const fs::path out = freshDir("sweep_issue");
    const CliRun r = runCli("sweep " + study.string() + " --out " + out.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    const std::vector<json> rs = rows(out);
    ASSERT_EQ(rs.size(), 4u);
    const std::vector<std::pair<int, int>> expected = {{4096, 1}, {4096, 2}, {32768, 1}, {32768, 2}};
    for (std::size_t i = 0; i < 4; ++i) {
        const json& row = rs[i];
        EXPECT_EQ(row["id"], "p000" + std::to_string(i));
        EXPECT_EQ(row["workload"], "builtin:cornell");
        EXPECT_EQ(row["overrides"]["cache.sizeBytes"], expected[i].first);
        EXPECT_EQ(row["overrides"]["traversal.units"], expected[i].second);
        ASSERT_TRUE(row["metrics"]["cycles"].is_number()) << row.dump();
        EXPECT_GT(row["metrics"]["cycles"].get<double>(), 0.0);
        EXPECT_GT(row["metrics"]["raysPerCycle"].get<double>(), 0.0);
        EXPECT_GE(row["metrics"]["cacheHitRate"].get<double>(), 0.0);
        EXPECT_LE(row["metrics"]["cacheHitRate"].get<double>(), 1.0);
        EXPECT_EQ(row["metrics"]["raysTraced"], 64 * 64);
        EXPECT_GT(row["timing"]["wallSeconds"].get<double>(), 0.0);
        // The point's stats.json is the render's, with the overrides applied.
        std::ifstream in(out / "points" / row["id"].get<std::string>() / "stats.json");
        const json stats = json::parse(in);
        EXPECT_EQ(stats["rtcore"]["config"]["cache"]["sizeBytes"], expected[i].first);
        EXPECT_EQ(stats["rtcore"]["config"]["traversal"]["units"], expected[i].second);
        EXPECT_EQ(stats["frames"][0]["rtcore"]["frame"]["cycles"], row["metrics"]["cycles"]);
    }
    // The overrides reach the model: an 8x larger node cache moves fewer bytes.
    EXPECT_GT(rs[0]["metrics"]["memoryBytes"].get<double>(), rs[2]["metrics"]["memoryBytes"].get<double>());
    const std::string csv = readText(out / "results.csv");
    EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 5);
    EXPECT_EQ(csv.substr(0, csv.find('\n')).find("id,workload,cache.sizeBytes,traversal.units,"), 0u) << csv;
    EXPECT_NE(csv.find("p0003,builtin:cornell,32768,2,"), std::string::npos) << csv;
    // Not a terminal: one line per finished point.
    for (int i = 1; i <= 4; ++i)
        EXPECT_NE(r.out.find("sweep: points " + std::to_string(i) + "/4"), std::string::npos) << r.out;

    // A rerun of a complete sweep runs nothing and changes nothing.
    const std::string before = readText(out / "results.jsonl");
    const CliRun again = runCli("sweep " + study.string() + " --out " + out.string());
    ASSERT_EQ(again.exitCode, 0) << again.out;
    EXPECT_NE(again.out.find("4 already complete"), std::string::npos) << again.out;
    EXPECT_NE(again.out.find("0 to run"), std::string::npos) << again.out;
    EXPECT_EQ(readText(out / "results.jsonl"), before);
}

// Killed (SIGKILL, or SIGINT as Ctrl-C) after 2 of 10 points, a sweep run
// again keeps the finished points (not redone), does the rest, and ends with
// the rows of one uninterrupted run.
TEST_P(SweepKillAndResume, ResumesWithoutRedoingFinishedPoints) {
    const int sig = GetParam();
    const KillAndResumeRun r = killAndResume(sig == SIGKILL ? "kill9" : "int", sig);
    ASSERT_TRUE(r.started);
    ASSERT_TRUE(r.killedBySignal) << "the sweep finished before it could be killed: " << r.firstLog;
    if (sig == SIGINT) {
        EXPECT_NE(r.firstLog.find("sweep interrupted: complete points are kept"), std::string::npos) << r.firstLog;
    }
    ASSERT_GE(r.kept, 2u);
    ASSERT_LT(r.kept, 10u);
    EXPECT_EQ(r.before.size(), r.kept);
    // No render of the killed sweep lives on (they die with it): nothing changes the points.
    EXPECT_EQ(r.keptLater, r.kept);
    ASSERT_EQ(r.again.exitCode, 0) << r.again.out;
    EXPECT_NE(r.again.out.find(std::to_string(r.kept) + " already complete"), std::string::npos) << r.again.out;
    EXPECT_NE(r.again.out.find(std::to_string(10 - r.kept) + " to run"), std::string::npos) << r.again.out;
    EXPECT_EQ(r.after, r.before) << "a finished point was redone";
    ASSERT_EQ(r.resumed.size(), 10u);
    for (std::size_t i = 0; i < r.resumed.size(); ++i) EXPECT_EQ(r.resumed[i]["index"], i);
    ASSERT_EQ(r.once.exitCode, 0) << r.once.out;
    EXPECT_EQ(r.fresh, r.resumed);
}

INSTANTIATE_TEST_SUITE_P(Signals, SweepKillAndResume, ::testing::Values(SIGKILL, SIGINT),
                         [](const ::testing::TestParamInfo<int>& info) {
                             return std::string(info.param == SIGKILL ? "Sigkill" : "Sigint");
                         });

TEST(Sweep, TwoJobsGiveTheSameRowsAsOne) {
    const fs::path study = writeStudy("jobs", kSmallStudy);
    const fs::path one = freshDir("sweep_jobs1"), two = freshDir("sweep_jobs2");
    const CliRun a = runCli("sweep " + study.string() + " --out " + one.string() + " --jobs 1");
    ASSERT_EQ(a.exitCode, 0) << a.out;
    const CliRun b = runCli("sweep " + study.string() + " --out " + two.string() + " --jobs 2");
    ASSERT_EQ(b.exitCode, 0) << b.out;
    EXPECT_NE(b.out.find("2 at a time"), std::string::npos) << b.out;
    const std::vector<json> ra = rowsWithoutTiming(one);
    ASSERT_EQ(ra.size(), 6u);
    EXPECT_EQ(ra, rowsWithoutTiming(two));
    EXPECT_EQ(readText(one / "points/p0004/stats.json").size() > 0, true);
}

TEST(Sweep, MpiThreeRanksGiveTheSameRowsAsOneProcess) {
#ifndef RTLAB_TEST_MPIEXEC
    GTEST_SKIP() << "rtlab was built without MPI";
#else
    const fs::path study = writeStudy("mpi", kSmallStudy);
    const fs::path one = freshDir("sweep_mpi_local"), mpi = freshDir("sweep_mpi_ranks");
    const CliRun a = runCli("sweep " + study.string() + " --out " + one.string());
    ASSERT_EQ(a.exitCode, 0) << a.out;
    std::string launcher = std::string(RTLAB_TEST_MPIEXEC) + " -n 3 --oversubscribe";
    if (geteuid() == 0) launcher += " --allow-run-as-root";
#ifdef __SANITIZE_ADDRESS__
    // Under ASan (make test-asan) LeakSanitizer reports OpenMPI's own
    // allocations at exit (libmpi, and MCA components it has unloaded), so
    // the ranks run without leak detection; every other test checks rtlab's.
    const char* asanOptions = std::getenv("ASAN_OPTIONS");
    launcher += std::string(" -x ASAN_OPTIONS=") + (asanOptions && *asanOptions ? std::string(asanOptions) + ":" : "") +
                "detect_leaks=0";
#endif
    const std::string cmd =
        launcher + " " + RTLAB_CLI + " sweep " + study.string() + " --out " + mpi.string() + " 2>&1";
    std::string output;
    FILE* pipe = popen(cmd.c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    char buf[4096];
    while (fgets(buf, sizeof buf, pipe)) output += buf;
    const int status = pclose(pipe);
    ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << output;
    EXPECT_NE(output.find("2 at a time"), std::string::npos) << output;  // rank 0 hands out, ranks 1 and 2 render
    EXPECT_EQ(output.find("warning"), std::string::npos) << output;
    const std::vector<json> ra = rowsWithoutTiming(one);
    ASSERT_EQ(ra.size(), 6u);
    EXPECT_EQ(ra, rowsWithoutTiming(mpi));
#endif
}

TEST(Sweep, ChangedStudyUnderAnExistingDirIsRefused) {
    const fs::path study = writeStudy("changed", kSmallStudy);
    const fs::path out = freshDir("sweep_changed");
    ASSERT_EQ(runCli("sweep " + study.string() + " --out " + out.string() + " --jobs 2").exitCode, 0);
    // Formatting alone is no change.
    std::ofstream(study) << json::parse(kSmallStudy).dump(4);
    const CliRun same = runCli("sweep " + study.string() + " --out " + out.string());
    EXPECT_EQ(same.exitCode, 0) << same.out;
    json changed = json::parse(kSmallStudy);
    changed["grid"]["cache.sizeBytes"].push_back(65536);
    std::ofstream(study) << changed.dump();
    const std::string before = readText(out / "results.jsonl");
    const CliRun r = runCli("sweep " + study.string() + " --out " + out.string());
    EXPECT_EQ(r.exitCode, 2) << r.out;
    EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
    EXPECT_NE(r.out.find(study.string() + ": differs from the study whose results are in " + out.string()),
              std::string::npos)
        << r.out;
    EXPECT_EQ(readText(out / "results.jsonl"), before);
}

TEST(Sweep, BadStudiesExitTwoNamingFileAndKey) {
    const std::vector<std::pair<std::string, std::string>> cases = {
        {R"({"workloads": ["builtin:cornell"], "grdi": {}})", "grdi: unknown key"},
        {R"({"workloads": ["builtin:cornell"], "render": {"widht": 3}})", "render.widht: unknown key"},
        {R"({"workloads": ["builtin:cornell"], "grid": {"cache.sizeBytes": [3000]}})", "cache.sizeBytes"},
        {R"({"workloads": ["builtin:cornell"], "grid": {"cache.nope": [1]}})", "cache.nope"},
        {R"({"workloads": [{"rays": "a.rtrays", "scene": "builtin:cornell"}]})",
         "workloads[0].rays: a.rtrays: no such file or directory"},
        {R"({"render": {}})", "workloads: missing"},
        {R"({"workloads": ["builtin:cornell"], "render": {"backend": "embree"}, "grid": {"cache.ways": [2]}})",
         "render.backend"},
        {R"({"workloads": ["builtin:cornell"], "list": [{"scheduler.policy": "nope"}]})", "scheduler.policy"},
        // A point whose override has no effect is refused before anything runs, naming the point.
        {R"({"workloads": ["builtin:cornell"], "render": {"rtcoreConfig": "single-core"},
             "list": [{"cache.sizeBytes": 8192}, {"l2.sizeBytes": 65536}]})",
         "point p0001 (builtin:cornell, l2.sizeBytes=65536): l2.sizeBytes: has no effect here: l2.mode is ideal"},
        {R"({"workloads": ["builtin:cornell"], "render": {"rtcoreConfig": "no-such-preset"}})", "no-such-preset"},
        {"{not json", "not valid JSON"},
    };
    for (std::size_t i = 0; i < cases.size(); ++i) {
        const fs::path study = writeStudy("bad" + std::to_string(i), cases[i].first);
        const fs::path out = freshDir("sweep_bad" + std::to_string(i));
        const CliRun r = runCli("sweep " + study.string() + " --out " + out.string());
        EXPECT_EQ(r.exitCode, 2) << cases[i].first << "\n" << r.out;
        EXPECT_EQ(r.out.rfind("rtlab: " + study.string() + ": ", 0), 0u) << r.out;
        EXPECT_NE(r.out.find(cases[i].second), std::string::npos) << r.out;
        EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
        EXPECT_FALSE(fs::exists(out)) << "a bad study must not create " << out;
    }
}

TEST(Sweep, PointWithBadSceneStopsWithExitTwoNamingThePoint) {
    // A scene file that exists (checked when the study is read) but does not load (read by the point).
    const fs::path broken = freshDir("sweep_badscene_file") / "broken.gltf";
    fs::create_directories(broken.parent_path());
    std::ofstream(broken) << "{";
    const fs::path study = writeStudy(
        "badscene", R"({"workloads": [")" + broken.string() + R"("], "render": {"width": 16, "height": 16}})");
    const fs::path out = freshDir("sweep_badscene");
    const CliRun r = runCli("sweep " + study.string() + " --out " + out.string());
    EXPECT_EQ(r.exitCode, 2) << r.out;
    EXPECT_NE(r.out.find("point p0000 (" + broken.string() + ") exited with 2: " + broken.string()), std::string::npos)
        << r.out;
    EXPECT_TRUE(rows(out).empty());
    // An unknown builtin is refused before any point runs: one line, nothing written.
    const fs::path typo =
        writeStudy("typo", R"({"workloads": ["builtin:nope"], "render": {"width": 16, "height": 16}})");
    const fs::path typoOut = freshDir("sweep_typo");
    const CliRun refused = runCli("sweep " + typo.string() + " --out " + typoOut.string());
    EXPECT_EQ(refused.exitCode, 2) << refused.out;
    EXPECT_EQ(refused.out, "rtlab: " + typo.string() +
                               ": workloads[0]: builtin:nope: unknown builtin scene (available: showcase, cornell, "
                               "terrain, forest, hairball, slivers)\n");
    EXPECT_FALSE(fs::exists(typoOut / "results.jsonl"));
    // So is a missing scene file.
    const fs::path missing = writeStudy("missing", R"({"workloads": ["builtin:cornell", "/nonexistent/scene.gltf"]})");
    const CliRun absent = runCli("sweep " + missing.string() + " --out " + freshDir("sweep_missing").string());
    EXPECT_EQ(absent.exitCode, 2) << absent.out;
    EXPECT_EQ(absent.out, "rtlab: " + missing.string() + ": workloads[1]: /nonexistent/scene.gltf: no such file\n");
}

TEST(Report, WritesSelfContainedHtmlWithPlotsTableConfigAndCommands) {
    const fs::path study = writeStudy("report", kSmallStudy);
    const fs::path out = freshDir("sweep_report");
    ASSERT_EQ(runCli("sweep " + study.string() + " --out " + out.string() + " --jobs 2").exitCode, 0);
    const CliRun r = runCli("report " + out.string());
    ASSERT_EQ(r.exitCode, 0) << r.out;
    const std::string html = readText(out / "report.html");
    // The plots inline as SVG (each point a <title>), also as files beside the page.
    EXPECT_NE(html.find("<figure><svg xmlns=\"http://www.w3.org/2000/svg\""), std::string::npos);
    EXPECT_NE(html.find("<title>p0000: builtin:cornell; cache.sizeBytes="), std::string::npos);
    EXPECT_EQ(html.find("<img "), std::string::npos);
    for (const char* ext : {".svg", ".pdf", ".csv"})
        EXPECT_TRUE(fs::exists(out / "plots" / (std::string("cycles-vs-cache.sizeBytes") + ext))) << ext;
    EXPECT_NE(r.out.find(" as PDF, summary in "), std::string::npos) << r.out;
    EXPECT_EQ(html.find("<script"), std::string::npos);
    EXPECT_EQ(html.find("src=\"http"), std::string::npos);
    EXPECT_EQ(html.find("src=\"file"), std::string::npos);
    for (int i = 0; i < 6; ++i) EXPECT_NE(html.find(">p000" + std::to_string(i) + "<"), std::string::npos) << i;
    EXPECT_NE(html.find("Base configuration"), std::string::npos);
    EXPECT_NE(html.find("&quot;sizeBytes&quot;: 32768"), std::string::npos);  // the resolved base config
    EXPECT_NE(html.find("rtlab sweep " + study.string() + " --out " + out.string()), std::string::npos);
    EXPECT_NE(html.find("rtlab render --scene builtin:cornell --width 32 --height 32"), std::string::npos);
    EXPECT_TRUE(fs::exists(out / "plots" / "cycles-vs-cache.sizeBytes.png"));

    const CliRun missing = runCli("report " + freshDir("report_missing").string());
    EXPECT_EQ(missing.exitCode, 2) << missing.out;
    EXPECT_NE(missing.out.find("not a sweep directory"), std::string::npos) << missing.out;
}

TEST(Sweep, OnATerminalOneProgressLineWithEta) {
    if (std::system("command -v script >/dev/null 2>&1") != 0)
        GTEST_SKIP() << "no script(1) to give the sweep a terminal";
    const fs::path study = writeStudy("tty", kIssueStudy);
    const fs::path out = freshDir("sweep_tty");
    // script(1) runs the sweep on a pseudo-terminal and copies what it wrote.
    const std::string cmd = "script -qec '" + std::string(RTLAB_CLI) + " sweep " + study.string() + " --out " +
                            out.string() + "' /dev/null 2>&1";
    std::string output;
    FILE* pipe = popen(cmd.c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    char buf[4096];
    while (fgets(buf, sizeof buf, pipe)) output += buf;
    ASSERT_EQ(pclose(pipe), 0) << output;
    EXPECT_NE(output.find("\r\033[Ksweep: points 0/4, running, ETA ?"), std::string::npos) << output;
    for (int i = 1; i <= 4; ++i)
        EXPECT_NE(output.find("\r\033[Ksweep: points " + std::to_string(i) + "/4, p000"), std::string::npos) << output;
    EXPECT_NE(output.find("ETA 0:0"), std::string::npos) << output;
    // No per-point log lines on a terminal: the line is rewritten in place.
    EXPECT_EQ(output.find("rtlab: sweep: points"), std::string::npos) << output;
    EXPECT_EQ(rows(out).size(), 4u);
}

// A ray-trace workload: recorded rays are replayed on the model at every
// point (traversal only); each row's cycles are those of `rtlab replay` with
// the same configuration.
TEST(Sweep, RecordedRaysAreReplayedAtEveryPoint) {
    const fs::path dir = freshDir("sweep_rays");
    const CliRun record = runCli(
        "render --scene builtin:cornell --effects gbuffer,shadows,ao --width 32 --height 32 "
        "--record-rays " +
        (dir / "rays").string() + " --out " + (dir / "render").string());
    ASSERT_EQ(record.exitCode, 0) << record.out;
    const fs::path study = writeStudy(
        "rays", R"({"workloads": [{"scene": "builtin:cornell", "rays": ")" + (dir / "rays").string() + R"("}],
      "render": {"backend": "rtcore", "rtcoreConfig": "single-core"},
      "grid": {"cache.sizeBytes": [1024, 32768]}})");
    const fs::path out = dir / "sweep";
    const CliRun sweep = runCli("sweep " + study.string() + " --out " + out.string());
    ASSERT_EQ(sweep.exitCode, 0) << sweep.out;
    const std::vector<json> rs = rows(out);
    ASSERT_EQ(rs.size(), 2u);
    const CliRun replay =
        runCli("replay --scene builtin:cornell --rays " + (dir / "rays").string() +
               " --backend rtcore --rtcore-config single-core --rtcore-set cache.sizeBytes=1024 --out " +
               (dir / "replay").string());
    ASSERT_EQ(replay.exitCode, 0) << replay.out;
    std::ifstream in(dir / "replay" / "stats.json");
    const json replayed = json::parse(in);
    EXPECT_EQ(rs[0]["metrics"]["cycles"].get<double>(),
              replayed["frames"][0]["rtcore"]["frame"]["cycles"].get<double>());
    EXPECT_NE(rs[0]["metrics"]["cycles"], rs[1]["metrics"]["cycles"]);  // the cache size matters
    EXPECT_NE(rs[0]["workload"].get<std::string>().find("[rays "), std::string::npos) << rs[0].dump();
    // A ray-trace workload whose file is missing is a bad study (exit 2 naming the key).
    const fs::path missing =
        writeStudy("rays_missing", R"({"workloads": [{"scene": "builtin:cornell", "rays": "nowhere.rays"}]})");
    const CliRun bad = runCli("sweep " + missing.string() + " --out " + (dir / "bad").string());
    EXPECT_EQ(bad.exitCode, 2) << bad.out;
    EXPECT_NE(bad.out.find("workloads[0].rays"), std::string::npos) << bad.out;
}
