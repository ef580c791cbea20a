// `rtlab render --record-rays DIR` and `rtlab replay` end to end: recording
// changes no pixel and is the same for any thread count; replay finds every
// recorded hit again on both back ends; on the RT-core model, replaying the
// frames gives exactly the render's cycle counts and stats (two cores sharing
// an L2 here); a file recorded on another scene, or damaged, exits 2 with one
// line; a differing hit exits 1.
#include "cli_test_util.hpp"

#include <rtlab/study/ray_trace_file.hpp>

#include <cstring>

using namespace rtlab::test;

namespace {

std::vector<char> bytesOf(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::vector<char>(std::istreambuf_iterator<char>(in), {});
}

nlohmann::json statsOf(const fs::path& dir) {
    std::ifstream in(dir / "stats.json");
    return nlohmann::json::parse(in);
}

const std::string kScene = "'builtin:terrain?triangles=3000&seed=2'";

// A version 2 file's batch, in place (docs/ray-trace-format.md, "Layout").
struct Batch {
    rtlab::study::BatchRecord* record;
    rtlab::study::RayRecord* rays;
    rtlab::study::BatchLaunchRecord* launch;
    rtlab::study::RayLinkRecord* links;
    std::uint32_t* verdicts;
};
template <class Fn>
void forEachBatch(std::vector<char>& bytes, Fn&& fn) {
    const auto* header = reinterpret_cast<const rtlab::study::RayTraceHeader*>(bytes.data());
    std::size_t offset = sizeof(rtlab::study::RayTraceHeader);
    for (std::uint64_t b = 0; b < header->batchCount; ++b) {
        Batch batch;
        batch.record = reinterpret_cast<rtlab::study::BatchRecord*>(bytes.data() + offset);
        offset += sizeof(rtlab::study::BatchRecord);
        batch.rays = reinterpret_cast<rtlab::study::RayRecord*>(bytes.data() + offset);
        offset += batch.record->rays * sizeof(rtlab::study::RayRecord);
        batch.launch = reinterpret_cast<rtlab::study::BatchLaunchRecord*>(bytes.data() + offset);
        offset += sizeof(rtlab::study::BatchLaunchRecord);
        batch.links = reinterpret_cast<rtlab::study::RayLinkRecord*>(bytes.data() + offset);
        offset += batch.record->rays * sizeof(rtlab::study::RayLinkRecord);
        batch.verdicts = reinterpret_cast<std::uint32_t*>(bytes.data() + offset);
        offset += (batch.launch->verdictWords + batch.launch->verdictWords % 2) * sizeof(std::uint32_t);
        fn(batch);
    }
}
// The body checksum made consistent again after an edit.
void resum(std::vector<char>& bytes) {
    auto* header = reinterpret_cast<rtlab::study::RayTraceHeader*>(bytes.data());
    rtlab::study::Fnv64 sum;
    sum.add(bytes.data() + sizeof(rtlab::study::RayTraceHeader), header->bodyBytes);
    header->bodyChecksum = sum.value();
}
const std::string kRender =
    "render --scene " + kScene + " --effects shadows,ao,pathtrace --max-depth 2 --width 32 --height 24 --frames 2";

}  // namespace

TEST(CliRayReplay, RecordingChangesNoPixelAndIsTheSameOnOneAndTwoThreads) {
    const fs::path plain = freshDir("rec_plain"), r1 = freshDir("rec_t1"), r2 = freshDir("rec_t2");
    ASSERT_EQ(runCli(kRender + " --out " + plain.string()).exitCode, 0);
    const CliRun one =
        runCli(kRender + " --threads 1 --record-rays " + (r1 / "rays").string() + " --out " + r1.string());
    ASSERT_EQ(one.exitCode, 0) << one.out;
    const CliRun two =
        runCli(kRender + " --threads 2 --record-rays " + (r2 / "rays").string() + " --out " + r2.string());
    ASSERT_EQ(two.exitCode, 0) << two.out;
    for (const char* frame : {"frame_0000", "frame_0001"}) {
        const CliRun c = runCli("compare " + (plain / (std::string(frame) + ".exr")).string() + " " +
                                (r1 / (std::string(frame) + ".exr")).string());
        EXPECT_NE(c.out.find("identical: true"), std::string::npos) << frame << c.out;
        const fs::path a = r1 / "rays" / (std::string(frame) + ".rays"),
                       b = r2 / "rays" / (std::string(frame) + ".rays");
        ASSERT_TRUE(fs::exists(a)) << a;
        EXPECT_EQ(bytesOf(a), bytesOf(b)) << frame;
        EXPECT_FALSE(fs::exists(a.string() + ".tmp"));
    }
    // stats.json names each frame's file and its ray count: every ray the frame traced.
    const nlohmann::json s = statsOf(r1);
    for (const auto& f : s["frames"]) {
        long long traced = 0;
        for (const auto& [type, counts] : f["rays"].items()) traced += counts["traced"].get<long long>();
        EXPECT_EQ(f["recordedRays"]["rays"].get<long long>(), traced);
        // About 72 bytes per ray (64 + an 8-byte link; plus 48 per trace call
        // and the header; this recording on Embree has no verdicts).
        const auto bytes = fs::file_size(f["recordedRays"]["file"].get<std::string>());
        EXPECT_LE(double(bytes), 80.0 * double(traced) + 128) << bytes << " bytes for " << traced << " rays";
    }
}

TEST(CliRayReplay, ReplayOnTheModelGivesTheRendersCyclesAndStatsExactly) {
    const fs::path dir = freshDir("rec_rtcore");
    const std::string config =
        " --backend rtcore --rtcore-set cache.sizeBytes=4096 --rtcore-set gpu.cores=2 --rtcore-set l2.mode=cache";
    const CliRun render =
        runCli(kRender + config + " --record-rays " + (dir / "rays").string() + " --out " + dir.string());
    ASSERT_EQ(render.exitCode, 0) << render.out;
    const fs::path out = dir / "replay";
    const CliRun replay =
        runCli("replay --scene " + kScene + " --rays " + (dir / "rays").string() + config + " --out " + out.string());
    ASSERT_EQ(replay.exitCode, 0) << replay.out;
    const nlohmann::json rendered = statsOf(dir), replayed = statsOf(out);
    EXPECT_EQ(rendered["rtcore"]["config"], replayed["rtcore"]["config"]);
    ASSERT_EQ(replayed["frames"].size(), 2u);
    for (std::size_t f = 0; f < 2; ++f) {
        nlohmann::json a = rendered["frames"][f]["rtcore"];
        const nlohmann::json& b = replayed["frames"][f]["rtcore"];
        for (const char* renderOnly : {"bvhUpdate", "heatmap", "verify"}) a.erase(renderOnly);
        EXPECT_EQ(a, b) << "frame " << f;
        EXPECT_GT(a.dump().size(), 100u);
        EXPECT_EQ(replayed["frames"][f]["differingHits"], 0);
        EXPECT_EQ(replayed["frames"][f]["notBitIdentical"], 0);
        EXPECT_EQ(replayed["frames"][f]["recordedOn"], "rtcore");
        EXPECT_GT(replayed["frames"][f]["rays"]["pathBounce"]["traced"].get<long long>(), 0);
    }
    // The same rays on Embree: every hit found again (the back ends agree).
    const CliRun embree = runCli("replay --scene " + kScene + " --rays " + (dir / "rays").string() + " --out " +
                                 (dir / "replay_embree").string());
    EXPECT_EQ(embree.exitCode, 0) << embree.out;
    EXPECT_NE(embree.out.find(" 0 hit(s) differ"), std::string::npos) << embree.out;
    // One ray type alone (a per-type workload study): only its batches are traced.
    const CliRun bounces = runCli("replay --scene " + kScene + " --rays " + (dir / "rays").string() +
                                  " --ray-types pathBounce" + config + " --out " + (dir / "bounces").string());
    ASSERT_EQ(bounces.exitCode, 0) << bounces.out;
    const nlohmann::json b = statsOf(dir / "bounces")["frames"][0];
    ASSERT_EQ(b["rays"].size(), 1u) << b["rays"].dump();
    EXPECT_EQ(b["rays"]["pathBounce"]["traced"], rendered["frames"][0]["rays"]["pathBounce"]["traced"]);
    EXPECT_EQ(b["rtcore"]["frame"]["rays"], b["rays"]["pathBounce"]["traced"]);
    EXPECT_GT(b["rtcoreModelBytes"].get<long long>(), 0);
    EXPECT_EQ(
        runCli("replay --scene " + kScene + " --rays " + (dir / "rays").string() + " --ray-types glitter").exitCode, 2);
}

TEST(CliRayReplay, RenderAndReplayAgreeInBothFeedingsOnEveryRayType) {
    // Showcase with every effect and the path tracer (its alpha-masked
    // foliage runs any-hit shaders on every ray type: their recorded
    // verdicts are replayed), forest (instancing) and terrain, in launch and
    // in tile mode on two cores, and showcase on the default preset
    // (rtx2060-like: 30 cores, a modelled L2 and DRAM): replay gives exactly
    // the render's cycles and statistics.
    const std::string everyEffect =
        " --effects alpha,shadows,reflections,translucency,ao,gi,volumes,pathtrace --max-depth 2";
    const std::vector<std::pair<std::string, std::string>> scenes = {
        {"builtin:showcase", everyEffect},
        {"'builtin:forest?instances=40'", " --effects shadows,ao,pathtrace --max-depth 2"},
        {kScene, " --effects shadows,reflections,ao,gi,pathtrace --max-depth 2"}};
    struct Case {
        std::string mode, scene, effects, config;
    };
    std::vector<Case> cases;
    for (const char* mode : {"launch", "tile"})
        for (const auto& [scene, effects] : scenes)
            cases.push_back({mode, scene, effects,
                             std::string(" --backend rtcore --rtcore-set gpu.launch=") + mode +
                                 " --rtcore-set gpu.cores=2 --rtcore-set l2.mode=cache"});
    cases.push_back({"default", "builtin:showcase", everyEffect, " --backend rtcore"});
    for (const Case& c : cases) {
        SCOPED_TRACE(c.mode + " " + c.scene);
        const fs::path dir = freshDir("modes_" + c.mode + "_" + std::to_string(c.scene.size()));
        const CliRun render = runCli("render --scene " + c.scene + c.effects + " --width 24 --height 16" + c.config +
                                     " --record-rays " + (dir / "rays").string() + " --out " + dir.string());
        ASSERT_EQ(render.exitCode, 0) << render.out;
        const CliRun replay = runCli("replay --scene " + c.scene + " --rays " + (dir / "rays").string() + c.config +
                                     " --out " + (dir / "replay").string());
        ASSERT_EQ(replay.exitCode, 0) << replay.out;
        nlohmann::json a = statsOf(dir)["frames"][0]["rtcore"];
        const nlohmann::json r = statsOf(dir / "replay")["frames"][0];
        for (const char* renderOnly : {"bvhUpdate", "heatmap", "verify"}) a.erase(renderOnly);
        EXPECT_EQ(a, r["rtcore"]);
        EXPECT_EQ(r["differingHits"], 0);
        EXPECT_EQ(a["backend"]["launch"], c.mode == "tile" ? "tile" : "launch");
        EXPECT_EQ(a["gpu"]["cores"], c.mode == "default" ? 30 : 2);
        EXPECT_GT(a["frame"]["rays"].get<long long>(), 0);
        if (c.scene == "builtin:showcase") {
            EXPECT_GT(a["shader"]["anyHitCalls"].get<long long>(), 0);
            EXPECT_GT(r["rays"]["pathBounce"]["traced"].get<long long>(), 0);
        }
    }
}

TEST(CliRayReplay, RecordedVerdictsThatDoNotMatchExitTwo) {
    // Showcase recorded on the model (alpha-masked foliage: any-hit verdicts);
    // one ray's verdict moved to its neighbour (the counts still add up, the
    // checksum made consistent): the replayed traversal meets candidates the
    // recording does not have, in launch and in tile mode: exit 2, one line.
    const fs::path dir = freshDir("rec_verdicts");
    const std::string config = " --backend rtcore --rtcore-set gpu.cores=2";
    ASSERT_EQ(runCli("render --scene builtin:showcase --width 24 --height 16" + config + " --record-rays " +
                     (dir / "rays").string() + " --out " + dir.string())
                  .exitCode,
              0);
    std::vector<char> bytes = bytesOf(dir / "rays" / "frame_0000.rays");
    bool moved = false;
    forEachBatch(bytes, [&](Batch& batch) {
        for (std::uint32_t i = 0; i + 1 < batch.record->rays && !moved; ++i)
            if (batch.links[i].verdicts > 0 && batch.links[i].verdicts != batch.links[i + 1].verdicts) {
                --batch.links[i].verdicts;
                ++batch.links[i + 1].verdicts;
                moved = true;
            }
    });
    ASSERT_TRUE(moved);
    resum(bytes);
    fs::create_directories(dir / "bad");
    {
        std::ofstream out(dir / "bad" / "frame_0000.rays", std::ios::binary);
        out.write(bytes.data(), std::streamsize(bytes.size()));
    }
    for (const char* mode : {"launch", "tile"}) {
        const CliRun r = runCli("replay --scene builtin:showcase --rays " + (dir / "bad").string() + config +
                                " --rtcore-set gpu.launch=" + mode + " --out " + (dir / mode).string());
        EXPECT_EQ(r.exitCode, 2) << mode << "\n" << r.out;
        EXPECT_NE(r.out.find("recorded verdicts"), std::string::npos) << mode << "\n" << r.out;
        EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << mode << "\n" << r.out;
    }
}

TEST(CliRayReplay, ForeignDamagedOrAlteredRecordingsAreRefused) {
    const fs::path dir = freshDir("rec_bad");
    ASSERT_EQ(runCli("render --scene builtin:cornell --effects gbuffer,shadows --width 16 --height 16 --record-rays " +
                     (dir / "rays").string() + " --out " + dir.string())
                  .exitCode,
              0);
    const fs::path file = dir / "rays" / "frame_0000.rays";
    const auto oneLine = [](const CliRun& r) { return std::count(r.out.begin(), r.out.end(), '\n') == 1; };
    // Another scene: the fingerprint differs.
    const CliRun foreign =
        runCli("replay --scene builtin:showcase --rays " + file.string() + " --out " + (dir / "o1").string());
    EXPECT_EQ(foreign.exitCode, 2) << foreign.out;
    EXPECT_NE(foreign.out.find("fingerprint"), std::string::npos) << foreign.out;
    EXPECT_TRUE(oneLine(foreign)) << foreign.out;
    // Truncated.
    std::vector<char> bytes = bytesOf(file);
    const fs::path truncated = dir / "truncated.rays";
    {
        std::ofstream out(truncated, std::ios::binary);
        out.write(bytes.data(), std::streamsize(bytes.size() - 100));
    }
    const CliRun cut =
        runCli("replay --scene builtin:cornell --rays " + truncated.string() + " --out " + (dir / "o2").string());
    EXPECT_EQ(cut.exitCode, 2) << cut.out;
    EXPECT_NE(cut.out.find(truncated.string()), std::string::npos) << cut.out;
    EXPECT_TRUE(oneLine(cut)) << cut.out;
    EXPECT_FALSE(fs::exists(dir / "o2" / "stats.json"));
    // Missing and empty inputs.
    EXPECT_EQ(runCli("replay --scene builtin:cornell --rays " + (dir / "nothing.rays").string()).exitCode, 2);
    fs::create_directories(dir / "empty");
    EXPECT_EQ(runCli("replay --scene builtin:cornell --rays " + (dir / "empty").string()).exitCode, 2);
    EXPECT_EQ(runCli("replay --scene builtin:cornell --rays " + file.string() + " --rtcore-set cache.ways=2").exitCode,
              2);
    // A recorded hit turned into a miss (checksum made consistent): replay finds a differing hit, exit 1.
    auto* header = reinterpret_cast<rtlab::study::RayTraceHeader*>(bytes.data());
    bool altered = false;
    forEachBatch(bytes, [&](Batch& batch) {
        for (std::uint32_t i = 0; i < batch.record->rays && !altered; ++i)
            if (batch.rays[i].flags & rtlab::study::RayRecord::kHit) {
                batch.rays[i].flags = 0;
                altered = true;
            }
    });
    ASSERT_TRUE(altered);
    resum(bytes);
    (void)header;
    const fs::path changed = dir / "changed.rays";
    {
        std::ofstream out(changed, std::ios::binary);
        out.write(bytes.data(), std::streamsize(bytes.size()));
    }
    const CliRun differ =
        runCli("replay --scene builtin:cornell --rays " + changed.string() + " --out " + (dir / "o3").string());
    EXPECT_EQ(differ.exitCode, 1) << differ.out;
    EXPECT_NE(differ.out.find(" 1 hit(s) differ"), std::string::npos) << differ.out;
    EXPECT_EQ(statsOf(dir / "o3")["frames"][0]["differingHits"], 1);
}
