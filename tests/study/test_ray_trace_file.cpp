// Ray-trace files (docs/ray-trace-format.md): a written file reads back bit
// for bit; truncated, padded, corrupt or foreign files are InputErrors that
// name the file; an unfinished writer leaves nothing behind; the scene
// fingerprint sees vertices and transforms.
#include <rtlab/core/error.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/ecs/world.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/study/ray_trace_file.hpp>
#include <rtlab/study/replay.hpp>

#include <gtest/gtest.h>
#include "temp_dir.hpp"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

using namespace rtlab;
using namespace rtlab::study;
namespace fs = std::filesystem;

namespace {

fs::path scratch(const std::string& name) {
    static const fs::path d = rtlab::test::freshTempDir("ray_trace_file_tests");
    fs::create_directories(d);
    fs::remove(d / name);
    return d / name;
}

// Two calls of seeded random rays (some lanes inactive, some hits) written to `path`.
struct Written {
    std::vector<std::vector<tracer::RayDesc>> rays;
    std::vector<std::vector<bool>> active;
    std::vector<std::vector<tracer::CommittedHit>> hits;
    std::vector<tracer::TraceArgs> args;
    std::vector<std::vector<std::uint32_t>> parents, counts, words;
};

Written writeSample(const fs::path& path, std::uint32_t seed = 7) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1e3f, 1e3f);
    Written w;
    RayTraceWriter writer(path);
    for (std::size_t call = 0; call < 2; ++call) {
        const std::size_t n = call == 0 ? 256 : 1;
        std::vector<tracer::RayDesc> rays(n);
        std::vector<tracer::CommittedHit> hits(n);
        std::unique_ptr<bool[]> active(new bool[n]);
        std::vector<bool> activeCopy(n);
        for (std::size_t i = 0; i < n; ++i) {
            rays[i] = tracer::RayDesc{vec3(u(rng), u(rng), u(rng)), 0.f, glm::normalize(vec3(u(rng), u(rng), u(rng))),
                                      i % 5 == 0 ? kInfinity : std::abs(u(rng))};
            active[i] = activeCopy[i] = (i % 3 != 1) || n == 1;
            if (i % 2 == 0) {
                hits[i].hit = true;
                hits[i].t = std::abs(u(rng));
                hits[i].instanceIndex = std::uint32_t(i);
                hits[i].geometryIndex = std::uint32_t(i % 4);
                hits[i].primitiveIndex = std::uint32_t(i * 7);
                hits[i].hitKind = 0xfe;
                hits[i].hitGroupRecord = std::uint32_t(i % 9);
                hits[i].attributes.values[0] = 0.25f;
                hits[i].attributes.values[1] = std::nextafter(0.5f, 1.f);
            }
        }
        tracer::TraceArgs a;
        a.rayFlags = call == 0 ? 0x1u : 0x4u;
        a.instanceInclusionMask = call == 0 ? 0xffu : 0x0fu;
        a.rayContribution = std::uint32_t(call) + 1;
        a.multiplier = 7;
        a.missIndex = std::uint32_t(call);
        // Launch `call`, its active lanes' parents (every second one has the
        // previous active lane's ray), i % 3 verdict words each.
        std::vector<std::uint32_t> parents, counts, words;
        for (std::size_t i = 0, k = 0; i < n; ++i) {
            if (!active[i]) continue;
            parents.push_back(k % 2 ? std::uint32_t(k - 1) : RayLinkRecord::kNoParent);
            counts.push_back(std::uint32_t(i % 3));
            for (std::size_t v = 0; v < i % 3; ++v) words.push_back(std::uint32_t(i * 10 + v));
            ++k;
        }
        BatchLaunch where;
        where.launch = std::uint32_t(call);
        where.launchThreads = std::uint32_t(n) + 5;
        where.threadBase = 5;
        where.parents = parents;
        where.verdictCounts = counts;
        where.verdictWords = words;
        writer.append(a, 1 + std::uint32_t(call), rays.data(), active.get(), hits.data(), n, where);
        w.parents.push_back(parents);
        w.counts.push_back(counts);
        w.words.push_back(words);
        w.rays.push_back(rays);
        w.active.push_back(activeCopy);
        w.hits.push_back(hits);
        w.args.push_back(a);
    }
    RayTraceInfo info;
    info.frame = 3;
    info.sceneFingerprint = 0x0123456789abcdefull;
    info.rayTypeCount = 7;
    info.hitGroupCount = 42;
    info.backend = RecordedBackend::RtCore;
    info.instanceCount = 5;
    info.uniqueTriangles = 1234;
    info.verdicts = true;
    writer.finish(info);
    return w;
}

std::vector<char> bytesOf(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::vector<char>(std::istreambuf_iterator<char>(in), {});
}
void writeBytes(const fs::path& p, const std::vector<char>& b) {
    std::ofstream out(p, std::ios::binary);
    out.write(b.data(), std::streamsize(b.size()));
}

// The InputError message of reading `path` ("" when it reads fine).
std::string readError(const fs::path& path) {
    try {
        RayTraceFile::read(path);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

}  // namespace

TEST(RayTraceFile, RoundTripKeepsEveryBitAndLane) {
    const fs::path path = scratch("round_trip.rays");
    const Written w = writeSample(path);
    EXPECT_FALSE(fs::exists(path.string() + ".tmp"));
    const RayTraceFile f = RayTraceFile::read(path);
    const RayTraceInfo info = f.info();
    EXPECT_EQ(info.frame, 3u);
    EXPECT_EQ(info.sceneFingerprint, 0x0123456789abcdefull);
    EXPECT_EQ(info.rayTypeCount, 7u);
    EXPECT_EQ(info.hitGroupCount, 42u);
    EXPECT_EQ(info.backend, RecordedBackend::RtCore);
    EXPECT_EQ(info.uniqueTriangles, 1234u);
    ASSERT_EQ(f.batches().size(), 2u);
    EXPECT_EQ(f.header().laneCount, 257u);
    std::uint64_t expectedRays = 0, wordBytes = 0;
    for (std::size_t b = 0; b < 2; ++b) {
        const RayTraceFile::Batch& batch = f.batches()[b];
        EXPECT_EQ(batch.record->lanes, w.rays[b].size());
        EXPECT_EQ(batch.record->depth, 1 + b);
        const tracer::TraceArgs a = batch.args();
        EXPECT_EQ(a.rayFlags, w.args[b].rayFlags);
        EXPECT_EQ(a.instanceInclusionMask, w.args[b].instanceInclusionMask);
        EXPECT_EQ(a.rayContribution, w.args[b].rayContribution);
        EXPECT_EQ(a.multiplier, w.args[b].multiplier);
        EXPECT_EQ(a.missIndex, w.args[b].missIndex);
        std::size_t next = 0;
        for (std::size_t lane = 0; lane < w.rays[b].size(); ++lane) {
            if (!w.active[b][lane]) continue;
            expectedRays++;
            ASSERT_LT(next, batch.rays.size());
            const RayRecord& r = batch.rays[next++];
            EXPECT_EQ(r.lane, lane);
            const tracer::RayDesc d = rayOf(r);
            EXPECT_EQ(std::memcmp(&d, &w.rays[b][lane], sizeof d), 0) << "lane " << lane;
            const tracer::CommittedHit h = hitOf(r), &e = w.hits[b][lane];
            EXPECT_EQ(h.hit, e.hit);
            if (!e.hit) continue;
            EXPECT_EQ(std::memcmp(&h.t, &e.t, sizeof(float)), 0);
            EXPECT_EQ(h.instanceIndex, e.instanceIndex);
            EXPECT_EQ(h.geometryIndex, e.geometryIndex);
            EXPECT_EQ(h.primitiveIndex, e.primitiveIndex);
            EXPECT_EQ(h.hitKind, e.hitKind);
            EXPECT_EQ(h.hitGroupRecord, e.hitGroupRecord);
            EXPECT_EQ(h.attributes.values[1], e.attributes.values[1]);
        }
        EXPECT_EQ(next, batch.rays.size());
        // Version 2: the launch, links and verdicts as written.
        ASSERT_NE(batch.launch, nullptr);
        EXPECT_EQ(batch.launch->launch, b);
        EXPECT_EQ(batch.launch->threadBase, 5u);
        EXPECT_EQ(batch.launch->launchThreads, w.rays[b].size() + 5);
        ASSERT_EQ(batch.links.size(), batch.rays.size());
        for (std::size_t k = 0; k < batch.links.size(); ++k) {
            EXPECT_EQ(batch.links[k].parent, w.parents[b][k]);
            EXPECT_EQ(batch.links[k].verdicts, w.counts[b][k]);
        }
        EXPECT_EQ(std::vector<std::uint32_t>(batch.verdicts.begin(), batch.verdicts.end()), w.words[b]);
        wordBytes += (w.words[b].size() + w.words[b].size() % 2) * 4;
    }
    EXPECT_EQ(f.header().rayCount, expectedRays);
    EXPECT_EQ(info.version, kRayTraceVersion);
    EXPECT_EQ(info.launches, 2u);
    EXPECT_TRUE(info.verdicts);
    // 128 bytes of header, 32 + 16 per call, 64 + 8 per ray, the verdict words padded to 8 bytes.
    EXPECT_EQ(fs::file_size(path), 128 + 2 * (32 + 16) + expectedRays * (64 + 8) + wordBytes);
}

// The same file in format version 1 (before launches): batch and ray
// records only, no launches, links or verdicts.
std::vector<char> asVersion1(const RayTraceFile& f) {
    std::vector<char> body;
    const auto put = [&](const void* p, std::size_t n) {
        body.insert(body.end(), static_cast<const char*>(p), static_cast<const char*>(p) + n);
    };
    for (const RayTraceFile::Batch& b : f.batches()) {
        put(b.record, sizeof(BatchRecord));
        put(b.rays.data(), b.rays.size_bytes());
    }
    RayTraceHeader h = f.header();
    h.version = 1;
    h.flags &= ~RayTraceHeader::kVerdicts;
    h.launchCount = 0;
    h.bodyBytes = body.size();
    Fnv64 sum;
    sum.add(body.data(), body.size());
    h.bodyChecksum = sum.value();
    std::vector<char> out(sizeof h + body.size());
    std::memcpy(out.data(), &h, sizeof h);
    if (!body.empty()) std::memcpy(out.data() + sizeof h, body.data(), body.size());
    return out;
}

TEST(RayTraceFile, Version1FilesAreReadAndReplayOnlyInTileMode) {
    const fs::path v2 = scratch("v2.rays"), v1 = scratch("v1.rays");
    writeSample(v2);
    const RayTraceFile now = RayTraceFile::read(v2);
    writeBytes(v1, asVersion1(now));
    const RayTraceFile old = RayTraceFile::read(v1);
    EXPECT_EQ(old.info().version, 1u);
    EXPECT_EQ(old.info().launches, 0u);
    EXPECT_FALSE(old.info().verdicts);
    ASSERT_EQ(old.batches().size(), now.batches().size());
    for (std::size_t b = 0; b < old.batches().size(); ++b) {
        EXPECT_EQ(old.batches()[b].launch, nullptr);
        EXPECT_TRUE(old.batches()[b].links.empty());
        ASSERT_EQ(old.batches()[b].rays.size(), now.batches()[b].rays.size());
        EXPECT_EQ(
            std::memcmp(old.batches()[b].rays.data(), now.batches()[b].rays.data(), now.batches()[b].rays.size_bytes()),
            0);
    }
    // On the model in launch mode it is refused, saying how to go on; in tile mode (and on Embree) it replays.
    rtcore_sim::RtCoreConfig config;
    const std::uint64_t fingerprint = old.info().sceneFingerprint;
    rtcore_sim::RtCoreBackend launch(config);
    try {
        checkReplayable(old, fingerprint, &launch);
        ADD_FAILURE() << "a version 1 file replayed in launch mode";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("gpu.launch=tile"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find(v1.string()), std::string::npos) << e.what();
    }
    config.gpu.launch = rtcore_sim::LaunchMode::Tile;
    rtcore_sim::RtCoreBackend tile(config);
    EXPECT_NO_THROW(checkReplayable(old, fingerprint, &tile));
    EXPECT_NO_THROW(checkReplayable(old, fingerprint, nullptr));
    EXPECT_NO_THROW(checkReplayable(now, fingerprint, &launch));
}

TEST(RayTraceFile, DamagedFilesAreInputErrorsNamingTheFile) {
    const fs::path good = scratch("good.rays");
    writeSample(good);
    const std::vector<char> bytes = bytesOf(good);
    const auto damaged = [&](const std::string& name, std::vector<char> b) {
        const fs::path p = scratch(name);
        writeBytes(p, b);
        const std::string error = readError(p);
        EXPECT_NE(error.find(p.string()), std::string::npos) << name << ": " << error;
        return error;
    };
    EXPECT_NE(damaged("empty.rays", {}).find("shorter than the header"), std::string::npos);
    EXPECT_NE(damaged("truncated.rays", std::vector<char>(bytes.begin(), bytes.end() - 10)).find("truncated"),
              std::string::npos);
    std::vector<char> padded = bytes;
    padded.push_back(0);
    EXPECT_NE(damaged("padded.rays", padded).find("truncated or padded"), std::string::npos);
    std::vector<char> magic = bytes;
    magic[0] = 'X';
    EXPECT_NE(damaged("magic.rays", magic).find("bad magic"), std::string::npos);
    std::vector<char> version = bytes;
    version[8] = 9;
    EXPECT_NE(damaged("version.rays", version).find("version 9"), std::string::npos);
    std::vector<char> flipped = bytes;
    flipped[128 + 32 + 5] ^= 0x10;  // a bit of the first ray's origin
    EXPECT_NE(damaged("flipped.rays", flipped).find("checksum"), std::string::npos);
    std::vector<char> counts = bytes;
    counts[24] ^= 1;  // batchCount
    EXPECT_NE(damaged("counts.rays", counts).find("corrupt"), std::string::npos);
    EXPECT_NE(readError(scratch("missing.rays")).find("cannot open"), std::string::npos);
    // Header fields the checksum does not cover, bounded by what a replay
    // would do with them: the frame (the scene is advanced to it) and the lanes.
    const auto withU32 = [&](std::size_t offset, std::uint32_t value) {
        std::vector<char> b = bytes;
        std::memcpy(b.data() + offset, &value, sizeof value);
        return b;
    };
    const fs::path lastFrame = scratch("last_frame.rays");  // scratch() removes the file
    writeBytes(lastFrame, withU32(64, 99999));
    EXPECT_EQ(readError(lastFrame), "");
    EXPECT_NE(damaged("frame.rays", withU32(64, 100000)).find("frame 100000; a render makes at most 100000 frames"),
              std::string::npos);
    std::vector<char> lanes = bytes;
    const std::uint64_t manyLanes = std::uint64_t(1) << 40;
    std::memcpy(lanes.data() + 32, &manyLanes, sizeof manyLanes);
    EXPECT_NE(damaged("lanes.rays", lanes).find("lanes, more than 65536 + 64 per body byte"), std::string::npos);
    // Random garbage of every length up to 300 bytes never crashes.
    std::mt19937 rng(11);
    for (std::size_t n = 0; n < 300; n += 7) {
        std::vector<char> garbage(n);
        for (char& c : garbage) c = char(rng());
        if (n >= 8) std::memcpy(garbage.data(), kRayTraceMagic, 8);
        EXPECT_FALSE(damaged("garbage.rays", garbage).empty()) << n;
    }
}

// The launches' threads (the model allocates and walks each) are bounded by
// the file's size: one launch of the most threads reads, two do not.
TEST(RayTraceFile, LaunchThreadsBeyondTheFilesSizeAreRefused) {
    const auto write = [](const fs::path& path, std::uint32_t launches) {
        RayTraceWriter writer(path);
        for (std::uint32_t launch = 0; launch < launches; ++launch) {
            const tracer::RayDesc ray{vec3(0.f), 0.f, vec3(0.f, 0.f, -1.f), 1.f};
            const tracer::CommittedHit hit{};
            const bool active[1] = {true};
            const std::vector<std::uint32_t> parents = {RayLinkRecord::kNoParent}, counts = {0};
            BatchLaunch where;
            where.launch = launch;
            where.launchThreads = rtcore_sim::kMaxLaunchThreads;
            where.threadBase = 0;
            where.parents = parents;
            where.verdictCounts = counts;
            writer.append(tracer::TraceArgs{}, 1, &ray, active, &hit, 1, where);
        }
        RayTraceInfo info;
        info.rayTypeCount = 7;
        info.backend = RecordedBackend::RtCore;
        info.verdicts = true;
        writer.finish(info);
    };
    const fs::path one = scratch("one_launch.rays"), two = scratch("two_launches.rays");  // scratch() removes the file
    write(one, 1);
    EXPECT_EQ(readError(one), "");
    write(two, 2);
    const std::string error = readError(two);
    EXPECT_NE(error.find("the launches declare 134217728 threads in all"), std::string::npos) << error;
}

TEST(RayTraceFile, AnUnfinishedWriterLeavesNoFile) {
    const fs::path path = scratch("unfinished.rays");
    {
        RayTraceWriter writer(path);
        const tracer::RayDesc ray;
        const bool active = true;
        const tracer::CommittedHit hit;
        const std::uint32_t parent = RayLinkRecord::kNoParent;
        BatchLaunch where;
        where.launchThreads = 1;
        where.parents = std::span(&parent, 1);
        writer.append(tracer::TraceArgs{}, 1, &ray, &active, &hit, 1, where);
        EXPECT_TRUE(fs::exists(path.string() + ".tmp"));
    }
    EXPECT_FALSE(fs::exists(path));
    EXPECT_FALSE(fs::exists(path.string() + ".tmp"));
}

TEST(RayTraceFile, FingerprintSeesVerticesAndTransforms) {
    ecs::World world;
    ecs::load::loadScene(world, "builtin:cornell");
    const ecs::SceneSnapshot scene = ecs::makeSnapshot(world, world.update(0.f));
    const std::uint64_t base = sceneFingerprint(scene);
    EXPECT_EQ(sceneFingerprint(scene), base);
    ecs::SceneSnapshot moved = scene;
    moved.instances[1].worldFromObject[3][0] = std::nextafter(moved.instances[1].worldFromObject[3][0], 1e9f);
    EXPECT_NE(sceneFingerprint(moved), base);
    std::vector<ecs::MeshAsset> meshes = *scene.meshes;
    meshes[0].geometries[0].positions[0].y += 1e-3f;
    ecs::SceneSnapshot deformed = scene;
    deformed.meshes = &meshes;
    EXPECT_NE(sceneFingerprint(deformed), base);
    ecs::World other;
    ecs::load::loadScene(other, "builtin:terrain?triangles=2000");
    EXPECT_NE(sceneFingerprint(ecs::makeSnapshot(other, other.update(0.f))), base);
}
