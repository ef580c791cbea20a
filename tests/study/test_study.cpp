// The study library: parsing STUDY files (errors name the key), points, the
// canonical form, render arguments, metrics from stats trees, the result
// store (resume, refusal of another study, the lock) and the report.
#include <rtlab/core/error.hpp>
#include <rtlab/study/metrics.hpp>
#include <rtlab/study/report.hpp>
#include <rtlab/study/result_store.hpp>
#include <rtlab/study/study.hpp>
#include <rtlab/study/summary.hpp>

#include <gtest/gtest.h>
#include "temp_dir.hpp"
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace fs = std::filesystem;
using namespace rtlab;
using namespace rtlab::study;
using nlohmann::json;

namespace {

const json kIssueStudy = json::parse(R"({"workloads": ["builtin:cornell"],
 "render": {"width": 64, "height": 64, "frames": 1, "effects": "gbuffer", "backend": "rtcore"},
 "grid": {"cache.sizeBytes": [4096, 32768], "traversal.units": [1, 2]}})");

std::string errorOf(const json& j) {
    try {
        parseStudy(j, "s.json");
    } catch (const InputError& e) {
        return e.what();
    }
    return "(no error)";
}

fs::path freshDir(const std::string& name) { return rtlab::test::freshTempDir("study_" + name); }

// A stats.json tree as `rtlab render --backend rtcore` writes it (the parts metrics read).
json fakeStats(double cycles0, double cycles1) {
    json s;
    s["frames"] = json::array();
    for (double c : {cycles0, cycles1}) {
        json f;
        f["rays"] = {{"primary", {{"traced", 100}}}, {"shadow", {{"traced", 50}}}};
        f["rtcore"]["frame"] = {{"cycles", c}, {"rays", 150}};
        f["rtcore"]["rays"]["latency"] = {{"mean", 10.0}, {"count", 150}};
        f["rtcore"]["cache"] = {{"hits", 30}, {"accesses", 40}};
        f["rtcore"]["memory"] = {{"readBytes", 640}, {"writeBytes", 0}};
        f["timing"] = {{"renderMs", 1.5}};
        s["frames"].push_back(f);
    }
    return s;
}

}  // namespace

TEST(StudyParse, IssueMinimalStudyHasFourPointsLastKeyFastest) {
    const Study s = parseStudy(kIssueStudy, "s.json");
    EXPECT_EQ(s.render.width, 64);
    EXPECT_EQ(s.render.effects, "gbuffer");
    EXPECT_EQ(s.render.denoise, "none");
    const std::vector<Point> points = expandPoints(s);
    ASSERT_EQ(points.size(), 4u);
    EXPECT_EQ(points[0].id, "p0000");
    EXPECT_EQ(points[3].id, "p0003");
    EXPECT_EQ(overrideValue(points[0], "cache.sizeBytes"), 4096);
    EXPECT_EQ(overrideValue(points[0], "traversal.units"), 1);
    EXPECT_EQ(overrideValue(points[1], "traversal.units"), 2);
    EXPECT_EQ(overrideValue(points[2], "cache.sizeBytes"), 32768);
    EXPECT_TRUE(overrideValue(points[2], "bvh.width").is_null());
    EXPECT_EQ(sweptParameters(s), (std::vector<std::string>{"cache.sizeBytes", "traversal.units"}));
}

TEST(StudyParse, GridThenListTimesWorkloads) {
    const Study s = parseStudy(json::parse(R"({"workloads": ["builtin:cornell", {"scene": "builtin:showcase"}],
        "base": {"memory.latency": 100},
        "grid": {"scheduler.policy": ["fifo", "treelet"]},
        "list": [{"cache.ways": 8, "scheduler.policy": "fifo"}]})"),
                               "s.json");
    const std::vector<Point> points = expandPoints(s);
    ASSERT_EQ(points.size(), 6u);
    EXPECT_EQ(points[2].overrides.size(), 2u);
    EXPECT_EQ(points[3].workload.scene, "builtin:showcase");
    EXPECT_EQ(overrideValue(points[4], "scheduler.policy"), "treelet");
    EXPECT_EQ(sweptParameters(s), (std::vector<std::string>{"scheduler.policy", "cache.ways"}));
    const rtcore_sim::RtCoreConfig c = resolveConfig(s, &points[2], "s.json");
    EXPECT_EQ(c.cache.ways, 8u);
    EXPECT_EQ(c.memory.latency, 100u);
    EXPECT_EQ(resolveConfig(s, nullptr, "s.json").memory.latency, 100u);
    // No parameter space: one point per workload.
    EXPECT_EQ(expandPoints(parseStudy(json::parse(R"({"workloads": ["builtin:cornell"]})"), "s.json")).size(), 1u);
}

// A workload may carry a camera (--camera's value): it reaches the point's
// render command, its label and the fingerprint; none leaves both as they were.
TEST(StudyParse, AWorkloadsCameraReachesItsRenderCommandAndLabel) {
    const Study s = parseStudy(json::parse(R"({"workloads": [{"scene": "builtin:cornell",
        "camera": "0,1,3,0,1,0,0,1,0,60"}, "builtin:cornell"]})"),
                               "s.json");
    const std::vector<Point> points = expandPoints(s);
    ASSERT_EQ(points.size(), 2u);
    EXPECT_EQ(points[0].workload.label(), "builtin:cornell [camera 0,1,3,0,1,0,0,1,0,60]");
    EXPECT_EQ(points[1].workload.label(), "builtin:cornell");
    EXPECT_NE(shellCommand(renderArguments(s, points[0], "o", 0)).find("--camera 0,1,3,0,1,0,0,1,0,60"),
              std::string::npos);
    EXPECT_EQ(shellCommand(renderArguments(s, points[1], "o", 0)).find("--camera"), std::string::npos);
    EXPECT_EQ(points[0].workload.toJson()["camera"], "0,1,3,0,1,0,0,1,0,60");
    EXPECT_FALSE(points[1].workload.toJson().contains("camera"));
    EXPECT_NE(
        s.fingerprint(),
        parseStudy(json::parse(R"({"workloads": ["builtin:cornell", "builtin:cornell"]})"), "s.json").fingerprint());
}

TEST(StudyParse, BadStudiesNameFileAndKey) {
    const std::vector<std::pair<std::string, std::string>> cases = {
        {R"([1])", "s.json: a study must be a JSON object"},
        {R"({"workloads": []})", "s.json: workloads: must be a non-empty list"},
        {R"({"workloads": [3]})", "s.json: workloads[0]: must be a scene source"},
        {R"({"workloads": [{"scene": "builtin:cornell", "x": 1}]})", "s.json: workloads[0].x: unknown key"},
        {R"({"workloads": [{"rays": "t.rtrays", "scene": "builtin:cornell"}]})",
         "s.json: workloads[0].rays: t.rtrays: no such file"},
        {R"({"workloads": [{"scene": "builtin:cornell", "camera": "0,0,1,0,0,1"}]})",
         "s.json: workloads[0].camera: eye and target are the same point"},
        // A builtin workload is checked before any point runs (a typo used to fail every point).
        {R"({"workloads": ["builtin:cornall"]})",
         "s.json: workloads[0]: builtin:cornall: unknown builtin scene (available: showcase, cornell"},
        {R"({"workloads": ["builtin:cornell", {"scene": "builtin:terrain?triangles=1"}]})",
         "s.json: workloads[1]: builtin:terrain?triangles=1: parameter 'triangles' is 1, out of range"},
        {R"({"workloads": [{"scene": "builtin:cornell", "camera": ""}]})",
         "s.json: workloads[0].camera: must be a non-empty string"},
        {R"({"workloads": ["builtin:cornell"], "render": {"camera": "0,0,1,0,0,0"}})",
         "s.json: render.camera: unknown key"},
        {R"({"workloads": ["builtin:cornell"], "objective": "speed"})", "s.json: objective: unknown metric 'speed'"},
        {R"({"workloads": ["builtin:cornell"], "objective": []})", "s.json: objective: must be a metric name"},
        {R"({"workloads": ["builtin:cornell"], "render": {"width": 0}})", "s.json: render.width: must be an integer"},
        {R"({"workloads": ["builtin:cornell"], "render": {"gi": "x"}})", "s.json: render.gi: must be one of"},
        // Unknown keys before any value; the effect lists checked as rtlab render checks them.
        {R"({"workloads": ["builtin:cornell"], "render": {"height": 0, "widht": 64}})",
         "s.json: render.widht: unknown key (known: width, height, spp"},
        {R"({"workloads": ["builtin:cornell"], "render": {"effects": "ao,glitter"}})",
         "s.json: render.effects: unknown effect 'glitter'"},
        {R"({"workloads": ["builtin:cornell"], "render": {"denoise": "pathtrace"}})",
         "s.json: render.denoise: unknown effect 'pathtrace'"},
        {R"({"workloads": ["builtin:cornell"], "render": {"maxDepth": 65}})",
         "s.json: render.maxDepth: must be an integer in 0..64"},
        {R"({"workloads": ["builtin:cornell"], "grid": {"cache.ways": []}})",
         "s.json: grid.cache.ways: must be a non-empty list"},
        {R"({"workloads": ["builtin:cornell"], "grid": {"cache.ways": [2, 2]}})",
         "s.json: grid.cache.ways: value 2 repeated"},
        {R"({"workloads": ["builtin:cornell"], "grid": {"cache.ways": [[2]]}})",
         "s.json: grid.cache.ways: must be a number"},
        {R"({"workloads": ["builtin:cornell"], "grid": {"bvh.width": [5]}})", "s.json: grid: bvh.width"},
        {R"({"workloads": ["builtin:cornell"], "base": {"nope.x": 1}})", "s.json: base: nope.x: unknown section"},
        {R"({"workloads": ["builtin:cornell"], "list": [{}]})", "s.json: list[0]: empty override set"},
        {R"({"workloads": ["builtin:cornell"], "list": [{"stack.refillEntries": 9}]})",
         "s.json: point p0000 (builtin:cornell, stack.refillEntries=9): stack.refillEntries"},
    };
    for (const auto& [text, expected] : cases)
        EXPECT_EQ(errorOf(json::parse(text)).rfind(expected, 0), 0u) << errorOf(json::parse(text));
}

// A study directory made before the options' table (22fb75e) resumes: the
// fingerprint of a study that sets no new render key is the one that build
// wrote (its results.jsonl for this study file), and a new key left at its
// default does not change it.
TEST(StudyParse, FingerprintsOfOlderStudiesStayTheSame) {
    const json older = json::parse(R"({"workloads": ["builtin:cornell"], "render": {"width": 8, "height": 8,
        "effects": "gbuffer"}, "grid": {"cache.sizeBytes": [4096]}})");
    EXPECT_EQ(parseStudy(older, "s.json").fingerprint(), "8aed1cd3eb8d38aa");
    json withDefault = older, withOther = older;
    withDefault["render"]["maxDepth"] = 4;
    withOther["render"]["maxDepth"] = 2;
    EXPECT_EQ(parseStudy(withDefault, "s.json").fingerprint(), "8aed1cd3eb8d38aa");
    EXPECT_NE(parseStudy(withOther, "s.json").fingerprint(), "8aed1cd3eb8d38aa");
    // A point renders with the option.
    const Study s = parseStudy(withOther, "s.json");
    const std::string line = shellCommand(renderArguments(s, expandPoints(s).at(0), "o", 0));
    EXPECT_NE(line.find("--max-depth 2"), std::string::npos) << line;
}

TEST(StudyParse, CanonicalFormIgnoresFormattingButNotContent) {
    const Study a = parseStudy(kIssueStudy, "a.json");
    const Study b = parseStudy(json::parse(R"({"grid": {"traversal.units": [1, 2], "cache.sizeBytes": [4096, 32768]},
        "render": {"backend": "rtcore", "effects": "gbuffer", "height": 64, "width": 64}, "workloads": ["builtin:cornell"]})"),
                               "b.json");
    EXPECT_EQ(a.fingerprint(), b.fingerprint());
    EXPECT_EQ(a.fingerprint().size(), 16u);
    json changed = kIssueStudy;
    changed["grid"]["traversal.units"] = {2, 1};  // order is part of the study (point ids)
    EXPECT_NE(parseStudy(changed, "c.json").fingerprint(), a.fingerprint());
    // The canonical form parses back to itself.
    EXPECT_EQ(parseStudy(a.toJson(), "x", false).toJson(), a.toJson());
}

TEST(StudyParse, RenderArgumentsAndShellQuoting) {
    const Study s = parseStudy(json::parse(R"({"workloads": ["builtin:terrain?triangles=2000"],
        "render": {"width": 8, "height": 4}, "base": {"memory.latency": 50}, "grid": {"scheduler.policy": ["treelet"]}})"),
                               "s.json");
    const Point p = expandPoints(s).at(0);
    const std::vector<std::string> args = renderArguments(s, p, "out/x", 3);
    const std::string line = shellCommand(args);
    EXPECT_EQ(line.rfind("render --scene 'builtin:terrain?triangles=2000' --width 8 --height 4 ", 0), 0u) << line;
    EXPECT_NE(line.find("--rtcore-set memory.latency=50 --rtcore-set scheduler.policy=treelet --threads 3 --out out/x"),
              std::string::npos)
        << line;
    EXPECT_EQ(shellCommand(renderArguments(s, p, "o", 0)).find("--threads"), std::string::npos);
    EXPECT_EQ(shellCommand({"a b", "it's"}), "'a b' 'it'\\''s'");
}

TEST(Metrics, SumsCountersOverFramesAndDerivesRates) {
    const json m = extractMetrics(fakeStats(100, 200));
    EXPECT_EQ(m["cycles"], 300);
    EXPECT_EQ(m["raysTraced"], 300);
    EXPECT_DOUBLE_EQ(m["raysPerCycle"].get<double>(), 1.0);
    EXPECT_DOUBLE_EQ(m["cacheHitRate"].get<double>(), 0.75);
    EXPECT_DOUBLE_EQ(m["meanLatency"].get<double>(), 10.0);
    EXPECT_EQ(m["memoryBytes"], 1280);
    EXPECT_DOUBLE_EQ(extractTimings(fakeStats(1, 1))["renderMs"].get<double>(), 3.0);
}

TEST(Metrics, AbsentStatisticsAreNullNotErrors) {
    json s = fakeStats(100, 200);
    EXPECT_TRUE(extractMetrics(s)["l2HitRate"].is_null());
    EXPECT_TRUE(extractMetrics(s)["dramBytes"].is_null());
    for (json& f : s["frames"]) {
        f["rtcore"]["l2"] = {{"hits", 1}, {"accesses", 4}};
        f["rtcore"]["dram"] = {{"readBytes", 64}};
    }
    EXPECT_DOUBLE_EQ(extractMetrics(s)["l2HitRate"].get<double>(), 0.25);
    EXPECT_EQ(extractMetrics(s)["dramBytes"], 128);
    s["frames"][1].erase("rtcore");  // an embree frame: no model statistics
    EXPECT_TRUE(extractMetrics(s)["cycles"].is_null());
    EXPECT_EQ(extractMetrics(s)["raysTraced"], 300);
    EXPECT_TRUE(extractMetrics(json::object())["cycles"].is_null());
    std::set<std::string> names;
    for (const MetricInfo& info : metricList()) EXPECT_TRUE(names.insert(info.name).second) << info.name;
    EXPECT_TRUE(names.count("wallSeconds"));
    EXPECT_EQ(extractMetrics(s).size() + extractTimings(s).size() + 1, metricList().size());  // + wallSeconds
}

TEST(ResultStore, RecordsResumesAndRefusesAnotherStudy) {
    const Study s = parseStudy(kIssueStudy, "s.json");
    const std::vector<Point> points = expandPoints(s);
    const fs::path dir = freshDir("store");
    {
        ResultStore store(dir, s, "s.json");
        EXPECT_EQ(store.doneCount(), 0u);
        // A second sweep on the same DIR meanwhile is refused.
        try {
            ResultStore second(dir, s, "s.json");
            ADD_FAILURE() << "the lock did not hold";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("another rtlab sweep"), std::string::npos) << e.what();
        }
        store.record(points[2], fakeStats(10, 20).dump(), 0.5);
        store.record(points[0], fakeStats(1, 2).dump(), 0.25);
        EXPECT_TRUE(store.isDone(points[0]));
        EXPECT_FALSE(store.isDone(points[1]));
    }
    EXPECT_TRUE(fs::exists(dir / "points/p0002/stats.json"));
    const std::vector<json> rows = readRows(dir);
    ASSERT_EQ(rows.size(), 2u);
    EXPECT_EQ(rows[0]["id"], "p0000");  // point order, not finishing order
    EXPECT_EQ(rows[1]["metrics"]["cycles"], 30);
    EXPECT_EQ(rows[1]["overrides"]["cache.sizeBytes"], 32768);
    EXPECT_DOUBLE_EQ(rows[1]["timing"]["wallSeconds"].get<double>(), 0.5);

    // A point whose result.json is missing (killed before it) runs again.
    fs::remove(dir / "points/p0002/result.json");
    {
        ResultStore store(dir, s, "s.json");
        EXPECT_EQ(store.doneCount(), 1u);
        EXPECT_FALSE(store.isDone(points[2]));
    }
    EXPECT_EQ(readRows(dir).size(), 1u);

    std::ifstream csvIn(dir / "results.csv");
    std::string header, line;
    std::getline(csvIn, header);
    std::getline(csvIn, line);
    EXPECT_EQ(header.rfind("id,workload,cache.sizeBytes,traversal.units,raysTraced,cycles,", 0), 0u) << header;
    EXPECT_NE(line.find(",,"), std::string::npos) << "absent metrics are empty cells: " << line;

    json other = kIssueStudy;
    other["render"]["width"] = 32;
    try {
        ResultStore store(dir, parseStudy(other, "t.json"), "t.json");
        ADD_FAILURE() << "another study was accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()).rfind("t.json: differs from the study whose results are in " + dir.string(), 0),
                  0u)
            << e.what();
    }
    const fs::path notSweep = freshDir("store_other");
    fs::create_directories(notSweep);
    std::ofstream(notSweep / "x.txt") << "x";
    EXPECT_THROW(ResultStore(notSweep, s, "s.json"), InputError);
}

TEST(Report, Escaping) { EXPECT_EQ(htmlEscape("<a href=\"x\">&</a>"), "&lt;a href=&quot;x&quot;&gt;&amp;&lt;/a&gt;"); }

TEST(Report, FromRecordedRowsDrawsOnePlotPerParameterAndMetric) {
    const Study s = parseStudy(json::parse(R"({"workloads": ["builtin:cornell"],
        "grid": {"cache.sizeBytes": [4096, 32768], "scheduler.policy": ["fifo", "treelet"]}})"),
                               "s.json");
    const std::vector<Point> points = expandPoints(s);
    const fs::path dir = freshDir("report");
    {
        ResultStore store(dir, s, "s.json");
        for (const Point& p : points) store.record(p, fakeStats(100 + p.index, 200).dump(), 0.1);
    }
    const ReportSummary r = writeReport(dir);
    EXPECT_EQ(r.rows, 4u);
    // cycles, raysPerCycle, meanLatency, cacheHitRate against each of the 2 parameters
    // (l2HitRate and dramBytes are absent from these stats).
    EXPECT_EQ(r.plots.size(), 8u);
    std::ifstream in(r.html);
    std::stringstream ss;
    ss << in.rdbuf();
    const std::string html = ss.str();
    std::size_t inlineSvgs = 0;
    for (std::size_t at = html.find("<svg "); at != std::string::npos; at = html.find("<svg ", at + 1)) ++inlineSvgs;
    EXPECT_EQ(inlineSvgs, 8u);
    EXPECT_EQ(r.svgs.size(), 8u);
    for (const fs::path& svg : r.svgs) {
        EXPECT_TRUE(fs::exists(svg)) << svg;
        EXPECT_TRUE(fs::exists(fs::path(svg).replace_extension(".csv"))) << svg;
    }
    EXPECT_TRUE(fs::exists(dir / "summary.json"));
    EXPECT_LT(html.find("id=\"summary\""), html.find("<h2>Plots</h2>"));
    EXPECT_NE(html.find("x is the category index: 1 = fifo, 2 = treelet"), std::string::npos);
    EXPECT_NE(html.find("builtin:cornell, scheduler.policy=treelet"), std::string::npos);  // a line per setting
    EXPECT_NE(html.find("rtlab sweep s.json --out " + dir.string()), std::string::npos);
    EXPECT_EQ(html.find("<script"), std::string::npos);
}

// The summary: per workload the best and worst point by each objective (its
// direction from the metric), per parameter its effect relative to its first
// value over pairs that differ in it alone.
TEST(Summary, BestWorstAndEachParametersEffect) {
    const Study s = parseStudy(json::parse(R"({"workloads": ["builtin:cornell"], "objective": ["cycles",
        "raysPerCycle"], "grid": {"cache.sizeBytes": [4096, 32768], "scheduler.policy": ["fifo", "treelet"]}})"),
                               "s.json");
    ASSERT_EQ(s.objectives, (std::vector<std::string>{"cycles", "raysPerCycle"}));
    std::vector<json> rows;
    const double cycles[4] = {100, 101, 102, 103};  // points in order: (4096, fifo), (4096, treelet), (32768, ...)
    for (const Point& p : expandPoints(s)) {
        json overrides = json::object();
        for (const Override& o : p.overrides) overrides[o.key] = o.value;
        rows.push_back({{"id", p.id},
                        {"workload", p.workload.label()},
                        {"overrides", overrides},
                        {"metrics", {{"cycles", cycles[p.index]}, {"raysPerCycle", 1000.0 / cycles[p.index]}}}});
    }
    const StudySummary summary = summarizeStudy(s, rows);
    ASSERT_EQ(summary.objectives.size(), 2u);
    const ObjectiveSummary& byCycles = summary.objectives[0];
    EXPECT_FALSE(byCycles.higherIsBetter);
    ASSERT_EQ(byCycles.workloads.size(), 1u);
    EXPECT_EQ(byCycles.workloads[0].best.id, "p0000");
    EXPECT_EQ(byCycles.workloads[0].best.configuration, "cache.sizeBytes=4096, scheduler.policy=fifo");
    EXPECT_EQ(byCycles.workloads[0].worst.id, "p0003");
    EXPECT_EQ(summary.objectives[1].workloads[0].best.id, "p0000") << "higher rays per cycle is better";
    EXPECT_TRUE(summary.objectives[1].higherIsBetter);
    ASSERT_EQ(byCycles.parameters.size(), 2u);
    const ParameterEffect& cache = byCycles.parameters[0];
    EXPECT_EQ(cache.parameter, "cache.sizeBytes");
    EXPECT_EQ(cache.baseValue, 4096);
    ASSERT_EQ(cache.values.size(), 2u);
    EXPECT_EQ(cache.values[0].pairs, 2u);
    EXPECT_DOUBLE_EQ(*cache.values[0].geometricMean, 1.0);
    EXPECT_NEAR(*cache.values[1].geometricMean, std::sqrt(102.0 / 100.0 * 103.0 / 101.0), 1e-12);
    EXPECT_DOUBLE_EQ(*cache.values[1].min, 103.0 / 101.0);
    EXPECT_DOUBLE_EQ(*cache.values[1].max, 102.0 / 100.0);
    const json j = summary.toJson();
    EXPECT_EQ(j["objectives"][0]["parameters"][1]["values"][1]["value"], "treelet");
    // How results are ranked does not change them: the fingerprint ignores the objective.
    EXPECT_EQ(s.fingerprint(), parseStudy(json::parse(R"({"workloads": ["builtin:cornell"], "grid":
        {"cache.sizeBytes": [4096, 32768], "scheduler.policy": ["fifo", "treelet"]}})"),
                                          "s.json")
                                   .fingerprint());
}

TEST(ResultStore, AcceptsWhatASweepKilledBeforeItsRecordLeaves) {
    const Study s = parseStudy(kIssueStudy, "s.json");
    const fs::path dir = freshDir("store_early_kill");
    fs::create_directories(dir / "points");
    std::ofstream(dir / ".lock") << "";
    {
        ResultStore store(dir, s, "s.json");
        EXPECT_EQ(store.doneCount(), 0u);
    }
    EXPECT_TRUE(fs::exists(dir / "study.json"));
    // Anything else in points/ is not ours to reuse.
    const fs::path other = freshDir("store_early_kill_other");
    fs::create_directories(other / "points" / "x");
    EXPECT_THROW(ResultStore(other, s, "s.json"), InputError);
}
