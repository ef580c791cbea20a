#pragma once
// The RT-core model's parameters (docs/rtcore-model.md): one typed struct per
// concern, each field with a default, a one-line description and a valid
// range, gem5 style. A ParamTable describes the fields of one struct; the
// RtCoreConfig groups the structs into named sections ("bvh", later the
// units), loads them from JSON, applies "section.field=value" overrides and
// dumps the resolved values (echoed into stats files).
//
// Bad input (unknown keys, wrong types, out-of-range values) throws
// rtlab::InputError naming the key, e.g. "cfg.json: bvh.width: must be one
// of 2, 4, 6, 8 (got 5)".
#include <rtlab/core/error.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace rtlab::rtcore_sim {

// ---------------------------------------------------------------------------
// Generic field descriptions.

enum class ParamKind : std::uint8_t { Unsigned, Real, Boolean, Choice };

// What the configuration knows about one parameter: enough to validate a
// value, print help and echo the default.
struct ParamInfo {
    std::string name;         // field name inside its section, e.g. "width"
    std::string description;  // one line
    ParamKind kind = ParamKind::Unsigned;
    nlohmann::json defaultValue;
    double min = 0.0;  // inclusive range (Unsigned, Real)
    double max = 0.0;
    std::vector<nlohmann::json> allowed;  // when non-empty, the only accepted values
    // Choice of a registry that can grow (scheduling policies registered
    // from outside the library): read when a value is checked, instead of `allowed`.
    std::vector<std::string> (*allowedNow)() = nullptr;
};

// Checks `value` against `info` and returns it in canonical form; throws
// InputError(where, "<key>: <problem>") otherwise.
nlohmann::json checkParamValue(const ParamInfo& info, const nlohmann::json& value, const std::string& where,
                               const std::string& key);

// One parameter with typed access to its member of Params.
template <class Params>
struct ParamField {
    ParamInfo info;
    std::function<nlohmann::json(const Params&)> read;
    std::function<void(Params&, const nlohmann::json&)> write;  // value already passed checkParamValue
};

// The fields of one parameter struct. Defaults are read from Params{}.
template <class Params>
class ParamTable {
public:
    ParamTable& addUnsigned(std::string name, std::uint32_t Params::*member, std::string description, std::uint32_t min,
                            std::uint32_t max) {
        ParamInfo info{std::move(name), std::move(description), ParamKind::Unsigned, {}, double(min), double(max), {},
                       nullptr};
        return add(std::move(info), member);
    }
    ParamTable& addUnsignedOneOf(std::string name, std::uint32_t Params::*member, std::string description,
                                 const std::vector<std::uint32_t>& allowed) {
        ParamInfo info{std::move(name), std::move(description), ParamKind::Unsigned, {}, 0.0, 0.0, {}, nullptr};
        for (std::uint32_t v : allowed) info.allowed.emplace_back(v);
        return add(std::move(info), member);
    }
    ParamTable& addReal(std::string name, float Params::*member, std::string description, float min, float max) {
        ParamInfo info{std::move(name), std::move(description), ParamKind::Real, {}, double(min), double(max), {},
                       nullptr};
        return add(std::move(info), member);
    }
    // A string chosen from a registry's current names (which may grow).
    ParamTable& addRegistryChoice(std::string name, std::string Params::*member, std::string description,
                                  std::vector<std::string> (*names)()) {
        ParamInfo info{std::move(name), std::move(description), ParamKind::Choice, {}, 0.0, 0.0, {}, names};
        return add(std::move(info), member);
    }
    template <class Enum>
    ParamTable& addChoice(std::string name, Enum Params::*member, std::string description,
                          std::vector<std::pair<std::string, Enum>> choices) {
        ParamField<Params> field;
        field.info = ParamInfo{std::move(name), std::move(description), ParamKind::Choice, {}, 0.0, 0.0, {}, nullptr};
        for (const auto& [label, value] : choices) field.info.allowed.emplace_back(label);
        field.read = [member, choices](const Params& p) -> nlohmann::json {
            for (const auto& [label, value] : choices)
                if (p.*member == value) return label;
            return nullptr;
        };
        field.write = [member, choices](Params& p, const nlohmann::json& v) {
            for (const auto& [label, value] : choices)
                if (v == label) p.*member = value;
        };
        field.info.defaultValue = field.read(Params{});
        fields_.push_back(std::move(field));
        return *this;
    }

    const std::vector<ParamField<Params>>& fields() const { return fields_; }
    const ParamField<Params>* find(std::string_view name) const {
        for (const ParamField<Params>& f : fields_)
            if (f.info.name == name) return &f;
        return nullptr;
    }

private:
    template <class T>
    ParamTable& add(ParamInfo info, T Params::*member) {
        ParamField<Params> field;
        field.info = std::move(info);
        field.read = [member](const Params& p) -> nlohmann::json { return p.*member; };
        field.write = [member](Params& p, const nlohmann::json& v) { p.*member = v.get<T>(); };
        field.info.defaultValue = field.read(Params{});
        fields_.push_back(std::move(field));
        return *this;
    }

    std::vector<ParamField<Params>> fields_;
};

// ---------------------------------------------------------------------------
// Parameter structs.

// Embree builder quality: low = Morton build, medium = binned SAH,
// high = binned SAH with spatial splits (SBVH; a triangle may then be
// referenced from several leaves).
enum class BuildQuality : std::uint8_t { Low, Medium, High };

// The bounding volume hierarchy the model traverses (section "bvh").
struct BvhParams {
    std::uint32_t width = 6;            // children per internal node
    std::uint32_t maxLeafSize = 4;      // triangles per BLAS leaf at most
    std::uint32_t tlasMaxLeafSize = 1;  // instances per TLAS leaf at most
    BuildQuality buildQuality = BuildQuality::Medium;
    float sahTraversalCost = 1.f;     // builder's cost of one node step (relative)
    float sahIntersectionCost = 1.f;  // builder's cost of one primitive test (relative)
    float refitRebuildThreshold =
        2.f;  // rebuild a refit BLAS once its SAH cost exceeds this multiple of its build cost
};
const ParamTable<BvhParams>& bvhParamTable();

// The timing model's units (docs/rtcore-model.md, "Timing model"). Every
// latency is in core cycles; every queue capacity in rays.

// Submission, ray slots and the completion path (section "core").
struct CoreParams {
    std::uint32_t warpWidth = 32;            // rays per submitted warp
    std::uint32_t inputQueueRays = 128;      // input queue capacity (a warp enters only whole)
    std::uint32_t raySlots = 128;            // rays traversing at once, each with its short stack
    std::uint32_t admitPerCycle = 4;         // rays moved from the input queue into free ray slots per cycle
    std::uint32_t completionQueueRays = 64;  // completion queue capacity
    std::uint32_t completionPerCycle = 4;    // results returned to the shader side per cycle
};
const ParamTable<CoreParams>& coreParamTable();

// The ray scheduler (section "scheduler").
struct SchedulerParams {
    std::string policy = "fifo";        // a name in the policy registry (scheduler.hpp)
    std::uint32_t issueWidth = 2;       // traversal steps issued per cycle
    std::uint32_t treeletBytes = 4096;  // treelet policy: bytes of BVH memory per treelet
    std::uint32_t prefetchBytes = 256;  // treeletPrefetch policy: bytes prefetched when a ray enters a treelet
};
const ParamTable<SchedulerParams>& schedulerParamTable();

// Box-test (traversal) units (section "traversal").
struct TraversalUnitParams {
    std::uint32_t units = 2;          // number of units
    std::uint32_t boxesPerCycle = 6;  // child boxes one unit tests per cycle
    std::uint32_t latency = 4;        // cycles from a unit's last issue cycle to its result
};
const ParamTable<TraversalUnitParams>& traversalParamTable();

// Primitive intersection units: watertight triangle tests and procedural AABB
// tests (section "triangle").
struct TriangleUnitParams {
    std::uint32_t units = 2;
    std::uint32_t testsPerCycle = 1;  // primitive tests one unit starts per cycle
    std::uint32_t latency = 8;
};
const ParamTable<TriangleUnitParams>& triangleParamTable();

// Instance-transform units (section "transform"): one world->object ray transform per unit per cycle.
struct TransformUnitParams {
    std::uint32_t units = 1;
    std::uint32_t latency = 4;
};
const ParamTable<TransformUnitParams>& transformParamTable();

// Round trips to the programmable side (section "shader").
struct ShaderParams {
    std::uint32_t anyHitLatency = 100;        // cycles per any-hit shader invocation
    std::uint32_t intersectionLatency = 100;  // cycles per intersection shader invocation
    std::uint32_t nextTraceLatency = 100;     // launch mode: cycles from a warp's results to its next TraceRay
};
const ParamTable<ShaderParams>& shaderParamTable();

// Per-ray traversal stack (section "stack"): a short on-chip stack that
// spills its bottom entries to memory and refills from it.
struct StackParams {
    std::uint32_t shortStackEntries = 8;  // on-chip entries per ray slot
    std::uint32_t refillEntries = 4;      // entries read back per refill
    std::uint32_t entryBytes = 8;         // bytes per stack entry in memory
};
const ParamTable<StackParams>& stackParamTable();

// Set-associative LRU node cache for BVH nodes, leaves and instances (section "cache").
struct CacheParams {
    std::uint32_t sizeBytes = 32768;
    std::uint32_t lineBytes = 64;
    std::uint32_t ways = 4;
    std::uint32_t hitLatency = 4;
    // Sectored lines (GPU L1s: 128-byte lines of 32-byte sectors): a line is
    // allocated whole, its sectors are looked up, read and counted one by one.
    // 0: unsectored (one sector = the line).
    std::uint32_t sectorBytes = 0;
    // The unit of a lookup and of a read below the cache.
    std::uint32_t fillBytes() const { return sectorBytes ? sectorBytes : lineBytes; }
};
const ParamTable<CacheParams>& cacheParamTable();

// Memory behind the cache (section "memory"): one channel, requests served in order.
struct MemoryParams {
    std::uint32_t latency = 200;       // cycles after a request's transfer until its data arrives
    std::uint32_t bytesPerCycle = 32;  // channel bandwidth
};
const ParamTable<MemoryParams>& memoryParamTable();

// The GPU level (section "gpu"): `cores` RT cores, each the core above with
// its own queues, units and private node cache (L1) and memory port, sharing
// the L2 and DRAM. Warps of a batch go to cores by `dispatch`.
enum class WarpDispatch : std::uint8_t {
    RoundRobin,  // warp w -> core w mod cores
    Contiguous,  // the batch's warps in `cores` contiguous runs (neighbouring pixels on one core)
};
// The order in which a batch's rays are cut into warps (src/policies/order_*.cpp).
enum class RayOrder : std::uint8_t {
    Submission,       // as submitted
    DirectionOrigin,  // sorted by direction octant, origin Morton code, direction Morton code
};
// How the pipeline's trace calls reach the model (docs/rtcore-model.md, "Launches").
enum class LaunchMode : std::uint8_t {
    Tile,    // every trace call is one RtCore::run batch, simulated before the call returns
    Launch,  // every dispatch is one launch: hits answered functionally, the launch simulated at its end
};
struct GpuParams {
    LaunchMode launch = LaunchMode::Launch;            // how trace calls reach the model
    std::uint32_t residentWarps = 32;                  // launch mode: warps of a launch resident per core at once
    std::uint32_t cores = 1;                           // RT cores
    WarpDispatch dispatch = WarpDispatch::RoundRobin;  // warp -> core rule
    RayOrder rayOrder = RayOrder::Submission;          // ray reordering before warp formation
};
const ParamTable<GpuParams>& gpuParamTable();

// The shared L2 (section "l2"). Mode ideal: every access hits and costs only
// the core's port (memory.*), exactly the single-core model; mode cache: a
// banked set-associative LRU cache in front of DRAM.
enum class L2Mode : std::uint8_t { Ideal, Cache };
// The order in which an L2 bank and a DRAM channel serve requests
// (docs/rtcore-model.md, "GPU level"): `Made` in the order the requests are
// made (a request waits behind every earlier-made one, even one still in
// another core's port queue); `Arrival` the first idle interval at or after
// the request's arrival (earlier-made requests keep their reservations).
enum class ServiceOrder : std::uint8_t { Made, Arrival };
struct L2Params {
    L2Mode mode = L2Mode::Ideal;
    ServiceOrder serviceOrder = ServiceOrder::Made;  // how banks and DRAM channels order their requests
    std::uint32_t sizeBytes = 4u << 20;              // capacity over all banks
    std::uint32_t lineBytes = 128;   // line size (>= the node cache's fill unit, CacheParams::fillBytes, in mode cache)
    std::uint32_t ways = 16;         // associativity
    std::uint32_t banks = 16;        // independent banks, line-interleaved
    std::uint32_t bankCycles = 1;    // cycles one access occupies its bank
    std::uint32_t hitLatency = 100;  // cycles from bank access to data on a hit
};
const ParamTable<L2Params>& l2ParamTable();

// DRAM behind the L2 (section "dram"): channels interleaved by L2 line, each
// serving its requests in order.
struct DramParams {
    std::uint32_t channels = 4;
    std::uint32_t bytesPerCycle = 16;  // per channel
    std::uint32_t latency = 200;       // cycles from the end of a request's transfer until its data is in the L2
};
const ParamTable<DramParams>& dramParamTable();

// ---------------------------------------------------------------------------
// The whole configuration.

// What a configuration drives: rendered or replayed frames (render, replay,
// sweep), or gpucheck-export's prediction: one launch, one thread per
// selected ray, no any-hit or intersection shader (docs/validation.md).
// Some parameters are inert in the second (RtCoreConfig::inertReason).
enum class ConfigUse : std::uint8_t { Frames, GpuCheckExport };

struct RtCoreConfig {
    BvhParams bvh;
    CoreParams core;
    SchedulerParams scheduler;
    TraversalUnitParams traversal;
    TriangleUnitParams triangle;
    TransformUnitParams transform;
    ShaderParams shader;
    StackParams stack;
    CacheParams cache;
    MemoryParams memory;
    GpuParams gpu;
    L2Params l2;
    DramParams dram;
    // A unit's parameters: a struct and table above, a member here and one
    // section line in config.cpp (forEachSection).

    // A JSON object {"section": {"field": value, ...}, ...}; absent fields
    // keep their defaults. Two keys document a file and are not sections:
    // "description" (a string) and "sources" (an object: "section.field" ->
    // where its value comes from). `where` names the source in error messages.
    static RtCoreConfig fromJson(const nlohmann::json& json, const std::string& where);
    // Reads and parses a JSON file (InputError names the file).
    static RtCoreConfig loadFile(const std::filesystem::path& path);
    // A preset by name (rtcorePresetNames()), or else a JSON file; "" is the
    // default preset (kDefaultRtCorePreset). What --rtcore-config and a
    // study's render.rtcoreConfig take.
    static RtCoreConfig load(const std::string& nameOrPath);

    // Overlays the fields present in `json` onto this configuration.
    void applyJson(const nlohmann::json& json, const std::string& where);
    // One override "section.field=value"; value is JSON (8, 1.5, true) or a
    // bare word for choices (bvh.buildQuality=high).
    // The key is remembered as set explicitly (checkExplicitKeys).
    void set(const std::string& assignment, const std::string& where = "--rtcore-set");

    // Keys given by set() (the command line's --rtcore-set, a study's
    // overrides), not those inherited from a preset or file.
    const std::vector<std::string>& explicitKeys() const { return explicitKeys_; }
    // InputError naming the first explicitly set key that has no effect in
    // this configuration, and what makes it inert (e.g. l2.sizeBytes while
    // l2.mode is ideal). Nothing set is silently ignored.
    void checkExplicitKeys(const std::string& where, ConfigUse use = ConfigUse::Frames) const;
    // Why `key` ("section.field") has no effect in this configuration; "" when it may have one.
    std::string inertReason(const std::string& key, ConfigUse use = ConfigUse::Frames) const;

    // Rules across fields (checked when an RtCore is built, and by the CLI
    // once all overrides are applied): core.inputQueueRays >= core.warpWidth,
    // stack.refillEntries <= stack.shortStackEntries, cache.sizeBytes a
    // power-of-two number of sets of cache.ways lines, l2.sizeBytes a
    // power-of-two number of sets of l2.ways lines per bank, and in l2 mode
    // cache l2.lineBytes >= cache.fillBytes(); cache.sectorBytes 0 or a divisor of
    // lineBytes with at most 32 sectors a line. Throws InputError.
    void validate(const std::string& where) const;

    // The resolved configuration, every field present.
    nlohmann::json toJson() const;
    // Every parameter: description, default, range or allowed values.
    static nlohmann::json describe();

private:
    std::vector<std::string> explicitKeys_;
};

// Named presets (rtcore_sim/presets/NAME.json, built into the library and
// installed to share/rtlab/rtcore-presets): each number's source is in the
// file's "sources".
inline constexpr const char* kDefaultRtCorePreset = "rtx2060-like";
// The most cache lines a configuration may model in all (validate): 2^24,
// about 0.5 GB of cache state; h100-like models about 0.7 million.
inline constexpr std::uint64_t kMaxModelCacheLines = std::uint64_t(1) << 24;
std::vector<std::string> rtcorePresetNames();
// The preset's JSON text; nullptr when there is no preset of that name.
const char* rtcorePresetText(const std::string& name);

std::string toString(BuildQuality quality);
std::string toString(WarpDispatch dispatch);
std::string toString(L2Mode mode);
std::string toString(ServiceOrder order);
std::string toString(RayOrder order);
std::string toString(LaunchMode mode);

}  // namespace rtlab::rtcore_sim
