#pragma once
// Ray-trace files (docs/ray-trace-format.md): every ray of one frame exactly
// as the pipeline submitted it to the traversal back end, batch by batch,
// with its committed hit, its launch, thread and parent, and (recorded on the
// RT-core model in launch mode) the verdicts of its candidates. Version 2
// layout, little-endian, every record naturally aligned so a reader can map
// the file and use the records in place:
//
//   RayTraceHeader (128 bytes)
//   per batch: BatchRecord (32 bytes),
//              BatchRecord::rays RayRecords (64 bytes each), one per active lane
//              of the call, in lane order (inactive lanes are not stored),
//              BatchLaunchRecord (16 bytes),
//              as many RayLinkRecords (8 bytes each),
//              BatchLaunchRecord::verdictWords verdict words (4 bytes each),
//              zero-padded to a multiple of 8 bytes
//
// Version 1 (before launches) had no BatchLaunchRecord, links or verdicts;
// it is still read (RayTraceInfo::version), and replays in tile mode only.
//
// Writing goes to "<path>.tmp", renamed on finish(); reading checks the
// magic, version, sizes, every batch tag and the body checksum, and throws
// InputError naming the file on any mismatch (exit 2 at the command line).
#include <rtlab/ecs/snapshot.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <span>
#include <vector>

namespace rtlab::study {

inline constexpr char kRayTraceMagic[8] = {'R', 'T', 'L', 'A', 'B', 'R', 'A', 'Y'};
inline constexpr std::uint32_t kRayTraceVersion = 2;
inline constexpr std::uint32_t kRayTraceOldestVersion = 1;
inline constexpr std::uint32_t kBatchTag = 0x48435442u;  // "BTCH"
// The most lanes one trace call may have (the pipeline's calls have at most
// 256, a tile): replay allocates per lane, so a reader cap keeps a 32-byte
// batch from asking for gigabytes.
inline constexpr std::uint32_t kMaxBatchLanes = 65536;
// Work a replay does per byte of a file's body, at most: lanes (a recorded
// tile of 256 lanes takes 32 bytes or more, so about 8 per byte) and launch
// threads (the model allocates and walks every thread of a launch: a
// 1920x1080 frame's launches, about 10 of 2 million threads, fit the base
// alone; a launch of many threads tracing few rays is a small file).
inline constexpr std::uint64_t kLanesPerBodyByte = 64;
inline constexpr std::uint64_t kLaunchThreadsPerBodyByte = 1024;

enum class RecordedBackend : std::uint32_t { Embree = 0, RtCore = 1 };

struct RayTraceHeader {
    char magic[8];                   // "RTLABRAY"
    std::uint32_t version;           // kRayTraceVersion
    std::uint32_t headerBytes;       // sizeof(RayTraceHeader) = 128
    std::uint64_t sceneFingerprint;  // sceneFingerprint() of the frame's snapshot
    std::uint64_t batchCount;
    std::uint64_t laneCount;      // lanes of all calls, inactive ones included
    std::uint64_t rayCount;       // ray records (active lanes)
    std::uint64_t bodyBytes;      // everything after the header
    std::uint64_t bodyChecksum;   // bodyChecksum() of those bytes
    std::uint32_t frame;          // frame index of the render
    std::uint32_t rayTypeCount;   // the shader table's ray-type stride
    std::uint32_t hitGroupCount;  // hit-group records in the shader table
    std::uint32_t backend;        // RecordedBackend that traced the rays
    std::uint32_t flags;          // kAnyHitShaders, kVerdicts
    std::uint32_t launchCount;    // version 2: launches of the frame (version 1: 0)
    std::uint64_t instanceCount;
    std::uint64_t uniqueTriangles;
    std::uint8_t reserved[24];
    static constexpr std::uint32_t kAnyHitShaders = 1;  // some hit group had an any-hit shader
    static constexpr std::uint32_t kVerdicts = 2;       // every batch carries its rays' candidate verdicts
};
static_assert(sizeof(RayTraceHeader) == 128);

// One trace call of the pipeline on the back end: its TraceRay arguments.
struct BatchRecord {
    std::uint32_t tag;    // kBatchTag
    std::uint32_t lanes;  // lanes of the call (its count), inactive ones included
    std::uint32_t rays;   // ray records that follow (its active lanes)
    std::uint32_t depth;  // recursion depth of the TraceRay calls
    std::uint32_t rayFlags;
    std::uint32_t instanceInclusionMask;
    std::uint16_t rayContribution;  // RayContributionToHitGroupIndex (the ray type)
    std::uint16_t multiplier;       // MultiplierForGeometryContributionToHitGroupIndex
    std::uint32_t missIndex;
};
static_assert(sizeof(BatchRecord) == 32);

// Version 2: which launch a call belongs to (docs/rtcore-model.md, "Launches").
struct BatchLaunchRecord {
    std::uint32_t launch;         // index of the launch in the frame (launches in order)
    std::uint32_t launchThreads;  // threads of that launch
    std::uint32_t threadBase;     // lane i of the call is thread threadBase + i
    std::uint32_t verdictWords;   // verdict words after the call's RayLinkRecords
};
static_assert(sizeof(BatchLaunchRecord) == 16);

// Version 2, per ray record: its parent and its verdicts.
struct RayLinkRecord {
    std::uint32_t parent;    // index among its launch's recorded rays of its thread's previous ray; ~0 for none
    std::uint32_t verdicts;  // its verdict words (rtcore_sim::LaunchLog encoding), in the batch's verdict block
    static constexpr std::uint32_t kNoParent = ~0u;
};
static_assert(sizeof(RayLinkRecord) == 8);

// One lane of a call: the ray as submitted and its committed hit.
struct RayRecord {
    float origin[3];
    float tMin;
    float direction[3];
    float tMax;
    float hitT;        // committed t (+inf on a miss)
    float hitU, hitV;  // barycentrics (HitAttributes::values[0..1])
    std::uint32_t instance;
    std::uint32_t primitive;
    std::uint32_t hitGroupRecord;
    std::uint16_t geometry;
    std::uint8_t hitKind;
    std::uint8_t flags;  // kHit
    std::uint32_t lane;  // the lane of the call (< BatchRecord::lanes, increasing within a batch)
    static constexpr std::uint8_t kHit = 1;
};
static_assert(sizeof(RayRecord) == 64);

// 64-bit FNV-1a over 8-byte little-endian words (a last partial word is
// zero-padded), offset basis 0xcbf29ce484222325, prime 0x100000001b3.
class Fnv64 {
public:
    void add(const void* data, std::size_t bytes);
    template <class T>
    void addValue(const T& v) {
        add(&v, sizeof v);
    }
    std::uint64_t value() const { return hash_; }

private:
    std::uint64_t hash_ = 0xcbf29ce484222325ull;
};

// What a recording must be replayed against: every mesh's vertex positions
// and indices (procedural boxes too), and every instance's mesh, transform,
// mask, flags, InstanceID and hit-group offset, in snapshot order.
std::uint64_t sceneFingerprint(const ecs::SceneSnapshot& scene);

struct RayTraceInfo {
    std::uint32_t frame = 0;
    std::uint64_t sceneFingerprint = 0;
    std::uint32_t rayTypeCount = 1;
    std::uint32_t hitGroupCount = 0;
    RecordedBackend backend = RecordedBackend::Embree;
    bool anyHitShaders = false;
    std::uint64_t instanceCount = 0;
    std::uint64_t uniqueTriangles = 0;
    std::uint32_t version = kRayTraceVersion;  // as read
    std::uint32_t launches = 0;                // version 2
    bool verdicts = false;                     // every batch carries its verdicts (recorded on rtcore, launch mode)
};

// Where a trace call sits in its launch, and its rays' links and verdicts
// (RayTraceWriter::append). parents/verdictCounts: one per active lane.
struct BatchLaunch {
    std::uint32_t launch = 0, launchThreads = 0, threadBase = 0;
    std::span<const std::uint32_t> parents;
    std::span<const std::uint32_t> verdictCounts;  // empty: no verdicts
    std::span<const std::uint32_t> verdictWords;
};

// Streams batches to "<path>.tmp"; finish() writes the header and renames
// the file to `path`. Destroying an unfinished writer removes the temporary.
class RayTraceWriter {
public:
    explicit RayTraceWriter(std::filesystem::path path);
    ~RayTraceWriter();
    RayTraceWriter(const RayTraceWriter&) = delete;
    RayTraceWriter& operator=(const RayTraceWriter&) = delete;

    void append(const tracer::TraceArgs& args, std::uint32_t depth, const tracer::RayDesc* rays, const bool* active,
                const tracer::CommittedHit* hits, std::size_t count, const BatchLaunch& launch);
    void finish(const RayTraceInfo& info);
    const std::filesystem::path& path() const { return path_; }
    std::uint64_t rays() const { return rays_; }

private:
    void write(const void* data, std::size_t bytes);

    std::filesystem::path path_, temporary_;
    std::FILE* file_ = nullptr;
    Fnv64 checksum_;
    std::uint64_t batches_ = 0, lanes_ = 0, rays_ = 0, bodyBytes_ = 0;
    std::uint32_t launches_ = 0;
    std::vector<RayRecord> scratch_;
    std::vector<RayLinkRecord> links_;
};

// A whole ray-trace file in memory, validated. Batches are views into it.
class RayTraceFile {
public:
    // Throws InputError("<path>", "...") for a missing, truncated or corrupt file.
    static RayTraceFile read(const std::filesystem::path& path);

    struct Batch {
        const BatchRecord* record;
        std::span<const RayRecord> rays;            // the active lanes
        const BatchLaunchRecord* launch = nullptr;  // version 2
        std::span<const RayLinkRecord> links;       // version 2: one per ray
        std::span<const std::uint32_t> verdicts;    // version 2 with verdicts
        tracer::TraceArgs args() const;
    };
    const RayTraceHeader& header() const { return header_; }
    RayTraceInfo info() const;
    const std::vector<Batch>& batches() const { return batches_; }
    const std::filesystem::path& path() const { return path_; }

private:
    std::filesystem::path path_;
    RayTraceHeader header_{};
    std::vector<std::uint64_t> storage_;  // the body, 8-byte aligned
    std::vector<Batch> batches_;
};

// A record's ray and hit in the pipeline's types.
tracer::RayDesc rayOf(const RayRecord& r);
tracer::CommittedHit hitOf(const RayRecord& r);

}  // namespace rtlab::study
