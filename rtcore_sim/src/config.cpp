#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/rtcore_sim/scheduler.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/json_nesting.hpp>

#include <algorithm>

#include <cmath>
#include <fstream>
#include <iterator>
#include <sstream>

namespace rtlab::rtcore_sim {
namespace {

std::string formatNumber(double v) {
    std::ostringstream out;
    out << v;
    return out.str();
}

std::string listAllowed(const std::vector<nlohmann::json>& allowed) {
    std::string s;
    for (std::size_t i = 0; i < allowed.size(); ++i) {
        if (i) s += ", ";
        s += allowed[i].is_string() ? allowed[i].get<std::string>() : allowed[i].dump();
    }
    return s;
}

std::vector<nlohmann::json> allowedValues(const ParamInfo& info) {
    if (!info.allowedNow) return info.allowed;
    std::vector<nlohmann::json> out;
    for (const std::string& name : info.allowedNow()) out.emplace_back(name);
    return out;
}

[[noreturn]] void fail(const std::string& where, const std::string& key, const std::string& problem) {
    throw InputError(where, key + ": " + problem);
}

// Every section of RtCoreConfig: fn(name, member pointer, table). Adding a
// unit's parameters is one line here.
template <class Fn>
void forEachSection(Fn&& fn) {
    fn("bvh", &RtCoreConfig::bvh, bvhParamTable());
    fn("core", &RtCoreConfig::core, coreParamTable());
    fn("scheduler", &RtCoreConfig::scheduler, schedulerParamTable());
    fn("traversal", &RtCoreConfig::traversal, traversalParamTable());
    fn("triangle", &RtCoreConfig::triangle, triangleParamTable());
    fn("transform", &RtCoreConfig::transform, transformParamTable());
    fn("shader", &RtCoreConfig::shader, shaderParamTable());
    fn("stack", &RtCoreConfig::stack, stackParamTable());
    fn("cache", &RtCoreConfig::cache, cacheParamTable());
    fn("memory", &RtCoreConfig::memory, memoryParamTable());
    fn("gpu", &RtCoreConfig::gpu, gpuParamTable());
    fn("l2", &RtCoreConfig::l2, l2ParamTable());
    fn("dram", &RtCoreConfig::dram, dramParamTable());
}

std::string knownSections() {
    std::string s;
    forEachSection([&](const char* name, auto, const auto&) { s += (s.empty() ? "" : ", ") + std::string(name); });
    return s;
}

template <class Params>
std::string knownFields(const ParamTable<Params>& table) {
    std::string s;
    for (const auto& f : table.fields()) s += (s.empty() ? "" : ", ") + f.info.name;
    return s;
}

// Sets section.field from a JSON value; false when the section is unknown.
bool setField(RtCoreConfig& config, const std::string& section, const std::string& field, const nlohmann::json& value,
              const std::string& where) {
    bool found = false;
    forEachSection([&](const char* name, auto member, const auto& table) {
        if (found || section != name) return;
        found = true;
        const std::string key = section + "." + field;
        const auto* f = table.find(field);
        if (!f) fail(where, key, "unknown key (known in \"" + section + "\": " + knownFields(table) + ")");
        f->write(config.*member, checkParamValue(f->info, value, where, key));
    });
    return found;
}

}  // namespace

nlohmann::json checkParamValue(const ParamInfo& info, const nlohmann::json& value, const std::string& where,
                               const std::string& key) {
    switch (info.kind) {
        case ParamKind::Unsigned: {
            if (!value.is_number_integer()) fail(where, key, "must be an unsigned integer (got " + value.dump() + ")");
            const std::int64_t v =
                value.is_number_unsigned()
                    ? static_cast<std::int64_t>(std::min<std::uint64_t>(value.get<std::uint64_t>(), INT64_MAX))
                    : value.get<std::int64_t>();
            if (!info.allowed.empty()) {
                for (const nlohmann::json& a : info.allowed)
                    if (a.get<std::int64_t>() == v) return nlohmann::json(static_cast<std::uint32_t>(v));
                fail(where, key, "must be one of " + listAllowed(info.allowed) + " (got " + value.dump() + ")");
            }
            if (double(v) < info.min || double(v) > info.max)
                fail(where, key,
                     "must be in [" + formatNumber(info.min) + ", " + formatNumber(info.max) + "] (got " +
                         value.dump() + ")");
            return nlohmann::json(static_cast<std::uint32_t>(v));
        }
        case ParamKind::Real: {
            if (!value.is_number()) fail(where, key, "must be a number (got " + value.dump() + ")");
            const double v = value.get<double>();
            if (!std::isfinite(v) || v < info.min || v > info.max)
                fail(where, key,
                     "must be in [" + formatNumber(info.min) + ", " + formatNumber(info.max) + "] (got " +
                         value.dump() + ")");
            return nlohmann::json(static_cast<float>(v));
        }
        case ParamKind::Boolean:
            if (!value.is_boolean()) fail(where, key, "must be true or false (got " + value.dump() + ")");
            return value;
        case ParamKind::Choice: {
            const std::vector<nlohmann::json> allowed = allowedValues(info);
            for (const nlohmann::json& a : allowed)
                if (value == a) return value;
            fail(where, key, "must be one of " + listAllowed(allowed) + " (got " + value.dump() + ")");
        }
    }
    fail(where, key, "unsupported parameter kind");
}

std::string toString(BuildQuality quality) {
    switch (quality) {
        case BuildQuality::Low: return "low";
        case BuildQuality::Medium: return "medium";
        case BuildQuality::High: return "high";
    }
    return "?";
}

const ParamTable<BvhParams>& bvhParamTable() {
    static const ParamTable<BvhParams> table = [] {
        ParamTable<BvhParams> t;
        t.addUnsignedOneOf("width", &BvhParams::width, "children per internal BVH node (both levels)", {2, 4, 6, 8});
        t.addUnsigned("maxLeafSize", &BvhParams::maxLeafSize, "most triangles referenced by one BLAS leaf", 1, 32);
        t.addUnsigned("tlasMaxLeafSize", &BvhParams::tlasMaxLeafSize, "most instances referenced by one TLAS leaf", 1,
                      32);
        t.addChoice("buildQuality", &BvhParams::buildQuality,
                    "Embree builder: low = Morton, medium = binned SAH, high = SAH with spatial splits (rigid meshes)",
                    std::vector<std::pair<std::string, BuildQuality>>{
                        {"low", BuildQuality::Low}, {"medium", BuildQuality::Medium}, {"high", BuildQuality::High}});
        t.addReal("sahTraversalCost", &BvhParams::sahTraversalCost,
                  "SAH cost of one node traversal step, for the builder", 0.001f, 1000.f);
        t.addReal("sahIntersectionCost", &BvhParams::sahIntersectionCost,
                  "SAH cost of one primitive intersection, for the builder", 0.001f, 1000.f);
        t.addReal("refitRebuildThreshold", &BvhParams::refitRebuildThreshold,
                  "rebuild a deformed BLAS instead of refitting once its SAH cost exceeds this multiple of its "
                  "build-time cost (0 = always refit)",
                  0.f, 1e6f);
        return t;
    }();
    return table;
}

const ParamTable<CoreParams>& coreParamTable() {
    static const ParamTable<CoreParams> table = [] {
        ParamTable<CoreParams> t;
        t.addUnsigned("warpWidth", &CoreParams::warpWidth, "rays per warp the shader side submits at once", 1, 64);
        t.addUnsigned("inputQueueRays", &CoreParams::inputQueueRays,
                      "input queue capacity in rays (a warp enters only when all its rays fit)", 1, 65536);
        t.addUnsigned("raySlots", &CoreParams::raySlots, "rays traversing at once, each with its own short stack", 1,
                      4096);
        t.addUnsigned("admitPerCycle", &CoreParams::admitPerCycle,
                      "rays moved from the input queue into free ray slots per cycle", 1, 64);
        t.addUnsigned("completionQueueRays", &CoreParams::completionQueueRays,
                      "completion queue capacity in rays (a finished ray keeps its slot while it is full)", 1, 65536);
        t.addUnsigned("completionPerCycle", &CoreParams::completionPerCycle,
                      "results returned to the shader side per cycle", 1, 64);
        return t;
    }();
    return table;
}

const ParamTable<SchedulerParams>& schedulerParamTable() {
    static const ParamTable<SchedulerParams> table = [] {
        ParamTable<SchedulerParams> t;
        t.addRegistryChoice("policy", &SchedulerParams::policy,
                            "which ready ray issues next: fifo, oldestFirst, treelet (Aila & Karras 2010 treelet "
                            "queues), treeletPrefetch (fifo + treelet prefetch into the L1, Chou et al. 2023) or a "
                            "policy registered with registerSchedulerPolicy",
                            &schedulerPolicyNames);
        t.addUnsigned("issueWidth", &SchedulerParams::issueWidth, "traversal steps the scheduler issues per cycle", 1,
                      64);
        t.addUnsigned("treeletBytes", &SchedulerParams::treeletBytes,
                      "treelet policy: BVH memory per treelet (a treelet = an aligned block of this many bytes)", 64,
                      1u << 24);
        t.addUnsigned("prefetchBytes", &SchedulerParams::prefetchBytes,
                      "treeletPrefetch policy: bytes read into the node cache from the address where a ray enters a "
                      "treelet (at most to the treelet's end)",
                      16, 1u << 24);
        return t;
    }();
    return table;
}

const ParamTable<TraversalUnitParams>& traversalParamTable() {
    static const ParamTable<TraversalUnitParams> table = [] {
        ParamTable<TraversalUnitParams> t;
        t.addUnsigned("units", &TraversalUnitParams::units, "box-test (traversal) units", 1, 64);
        t.addUnsigned("boxesPerCycle", &TraversalUnitParams::boxesPerCycle,
                      "child boxes one unit tests per cycle (a node occupies it ceil(children / this) cycles)", 1, 64);
        t.addUnsigned("latency", &TraversalUnitParams::latency, "cycles from a node's last issue cycle to its result",
                      1, 1000);
        return t;
    }();
    return table;
}

const ParamTable<TriangleUnitParams>& triangleParamTable() {
    static const ParamTable<TriangleUnitParams> table = [] {
        ParamTable<TriangleUnitParams> t;
        t.addUnsigned("units", &TriangleUnitParams::units,
                      "primitive intersection units (watertight triangle tests, procedural AABB tests)", 1, 64);
        t.addUnsigned("testsPerCycle", &TriangleUnitParams::testsPerCycle,
                      "primitive tests one unit starts per cycle (a leaf occupies it ceil(tests / this) cycles)", 1,
                      64);
        t.addUnsigned("latency", &TriangleUnitParams::latency, "cycles from a leaf's last issue cycle to its result", 1,
                      1000);
        return t;
    }();
    return table;
}

const ParamTable<TransformUnitParams>& transformParamTable() {
    static const ParamTable<TransformUnitParams> table = [] {
        ParamTable<TransformUnitParams> t;
        t.addUnsigned("units", &TransformUnitParams::units,
                      "instance-transform units (one world-to-object ray transform per unit per cycle)", 1, 64);
        t.addUnsigned("latency", &TransformUnitParams::latency, "cycles of one ray transform", 1, 1000);
        return t;
    }();
    return table;
}

const ParamTable<ShaderParams>& shaderParamTable() {
    static const ParamTable<ShaderParams> table = [] {
        ParamTable<ShaderParams> t;
        t.addUnsigned("anyHitLatency", &ShaderParams::anyHitLatency,
                      "cycles of one any-hit shader round trip to the programmable side", 0, 100000);
        t.addUnsigned("intersectionLatency", &ShaderParams::intersectionLatency,
                      "cycles of one intersection shader round trip to the programmable side", 0, 100000);
        t.addUnsigned("nextTraceLatency", &ShaderParams::nextTraceLatency,
                      "gpu.launch = launch: cycles from the last result of a warp's TraceRay to the warp's next "
                      "TraceRay (the closest-hit, miss or ray-generation code in between)",
                      0, 1000000);
        return t;
    }();
    return table;
}

const ParamTable<StackParams>& stackParamTable() {
    static const ParamTable<StackParams> table = [] {
        ParamTable<StackParams> t;
        t.addUnsigned("shortStackEntries", &StackParams::shortStackEntries,
                      "on-chip stack entries per ray slot; deeper entries spill to memory", 1, 64);
        t.addUnsigned("refillEntries", &StackParams::refillEntries,
                      "spilled entries read back by one refill (at most shortStackEntries)", 1, 64);
        t.addUnsigned("entryBytes", &StackParams::entryBytes, "bytes per stack entry in memory", 4, 64);
        return t;
    }();
    return table;
}

const ParamTable<CacheParams>& cacheParamTable() {
    static const ParamTable<CacheParams> table = [] {
        ParamTable<CacheParams> t;
        t.addUnsigned("sizeBytes", &CacheParams::sizeBytes,
                      "node cache capacity (a power-of-two number of sets of `ways` lines)", 16, 1u << 30);
        t.addUnsignedOneOf("lineBytes", &CacheParams::lineBytes, "cache line size", {16, 32, 64, 128, 256});
        t.addUnsigned("ways", &CacheParams::ways, "associativity (lines per set, LRU replacement)", 1, 64);
        t.addUnsigned("hitLatency", &CacheParams::hitLatency, "cycles from a fetch to its data on a hit", 1, 1000);
        t.addUnsignedOneOf("sectorBytes", &CacheParams::sectorBytes,
                           "sector size of sectored lines: lines allocated whole, sectors looked up, read and "
                           "counted one by one (0 = unsectored)",
                           {0, 16, 32, 64, 128});
        return t;
    }();
    return table;
}

const ParamTable<MemoryParams>& memoryParamTable() {
    static const ParamTable<MemoryParams> table = [] {
        ParamTable<MemoryParams> t;
        t.addUnsigned("latency", &MemoryParams::latency,
                      "cycles from the end of a request's transfer slot until its data arrives (l2 mode cache: "
                      "plus the L2 and DRAM time)",
                      1, 100000);
        t.addUnsigned("bytesPerCycle", &MemoryParams::bytesPerCycle,
                      "bandwidth of each core's memory port (a request of B bytes occupies it ceil(B / this) cycles)",
                      1, 4096);
        return t;
    }();
    return table;
}

std::string toString(WarpDispatch dispatch) {
    return dispatch == WarpDispatch::RoundRobin ? "roundRobin" : "contiguous";
}

std::string toString(L2Mode mode) { return mode == L2Mode::Ideal ? "ideal" : "cache"; }
std::string toString(ServiceOrder order) { return order == ServiceOrder::Made ? "made" : "arrival"; }

std::string toString(RayOrder order) { return order == RayOrder::Submission ? "submission" : "directionOrigin"; }
std::string toString(LaunchMode mode) { return mode == LaunchMode::Launch ? "launch" : "tile"; }

const ParamTable<GpuParams>& gpuParamTable() {
    static const ParamTable<GpuParams> table = [] {
        ParamTable<GpuParams> t;
        t.addChoice("launch", &GpuParams::launch,
                    "how the pipeline's trace calls reach the model: launch = each dispatch is one launch (its "
                    "threads' rays in flight together, a thread's next ray after its previous result); tile = each "
                    "trace call is one batch, simulated before the call returns (the model before launches)",
                    std::vector<std::pair<std::string, LaunchMode>>{{"launch", LaunchMode::Launch},
                                                                    {"tile", LaunchMode::Tile}});
        t.addUnsigned("residentWarps", &GpuParams::residentWarps,
                      "gpu.launch = launch: warps of a launch resident on one core at once (a warp stays resident "
                      "from its first TraceRay until its threads' last result)",
                      1, 4096);
        t.addUnsigned("cores", &GpuParams::cores,
                      "RT cores, each with its own queues, units, node cache (L1) and memory port, sharing l2 and dram",
                      1, 256);
        t.addChoice("dispatch", &GpuParams::dispatch,
                    "warp -> core rule: roundRobin = warp w to core w mod cores; contiguous = the batch's warps in "
                    "`cores` contiguous runs",
                    std::vector<std::pair<std::string, WarpDispatch>>{{"roundRobin", WarpDispatch::RoundRobin},
                                                                      {"contiguous", WarpDispatch::Contiguous}});
        t.addChoice(
            "rayOrder", &GpuParams::rayOrder,
            "ray reordering: submission = as submitted; directionOrigin = by direction octant, then origin and "
            "direction Morton codes (src/policies/order_direction_origin.cpp): a tile batch is sorted before warp "
            "formation, a launch's cores admit the rays waiting in their input queues in key order",
            std::vector<std::pair<std::string, RayOrder>>{{"submission", RayOrder::Submission},
                                                          {"directionOrigin", RayOrder::DirectionOrigin}});
        return t;
    }();
    return table;
}

const ParamTable<L2Params>& l2ParamTable() {
    static const ParamTable<L2Params> table = [] {
        ParamTable<L2Params> t;
        t.addChoice("mode", &L2Params::mode,
                    "ideal = every access hits at the cost of the core's port alone (the single-core model); cache = "
                    "banked set-associative LRU cache in front of dram",
                    std::vector<std::pair<std::string, L2Mode>>{{"ideal", L2Mode::Ideal}, {"cache", L2Mode::Cache}});
        t.addChoice("serviceOrder", &L2Params::serviceOrder,
                    "how each L2 bank and DRAM channel orders its requests: made = in the order they are made (a "
                    "request waits behind every earlier-made one, even one still in another core's port queue); "
                    "arrival = the first idle interval at or after the request's arrival (earlier-made requests "
                    "keep their reservations)",
                    std::vector<std::pair<std::string, ServiceOrder>>{{"made", ServiceOrder::Made},
                                                                      {"arrival", ServiceOrder::Arrival}});
        t.addUnsigned("sizeBytes", &L2Params::sizeBytes,
                      "L2 capacity over all banks (a power-of-two number of sets of `ways` lines per bank)", 1024,
                      1u << 30);
        t.addUnsignedOneOf("lineBytes", &L2Params::lineBytes, "L2 line size (at least cache.lineBytes in mode cache)",
                           {32, 64, 128, 256});
        t.addUnsigned("ways", &L2Params::ways, "associativity (lines per set, LRU replacement)", 1, 64);
        t.addUnsigned("banks", &L2Params::banks, "independent banks; line l is in bank l mod banks", 1, 256);
        t.addUnsigned("bankCycles", &L2Params::bankCycles,
                      "cycles one access occupies its bank (a later access to a busy bank waits: a bank conflict)", 1,
                      1000);
        t.addUnsigned("hitLatency", &L2Params::hitLatency,
                      "cycles from the bank access to the data leaving the L2 on a hit (the tag check before a miss)",
                      0, 100000);
        return t;
    }();
    return table;
}

const ParamTable<DramParams>& dramParamTable() {
    static const ParamTable<DramParams> table = [] {
        ParamTable<DramParams> t;
        t.addUnsigned("channels", &DramParams::channels, "DRAM channels; L2 line l is served by channel l mod channels",
                      1, 64);
        t.addUnsigned("bytesPerCycle", &DramParams::bytesPerCycle,
                      "bandwidth per channel (an L2 line fill occupies it ceil(l2.lineBytes / this) cycles)", 1, 4096);
        t.addUnsigned("latency", &DramParams::latency,
                      "cycles from the end of a request's transfer slot until its line is in the L2", 1, 100000);
        return t;
    }();
    return table;
}

void RtCoreConfig::validate(const std::string& where) const {
    if (gpu.residentWarps < 1 || gpu.residentWarps > 4096)
        fail(where, "gpu.residentWarps", "must be in [1, 4096] (got " + std::to_string(gpu.residentWarps) + ")");
    if (core.inputQueueRays < core.warpWidth)
        fail(where, "core.inputQueueRays",
             "must be at least core.warpWidth (" + std::to_string(core.warpWidth) + ") so that a warp fits (got " +
                 std::to_string(core.inputQueueRays) + ")");
    if (stack.refillEntries > stack.shortStackEntries)
        fail(where, "stack.refillEntries",
             "must be at most stack.shortStackEntries (" + std::to_string(stack.shortStackEntries) + ") (got " +
                 std::to_string(stack.refillEntries) + ")");
    const std::uint64_t setBytes = std::uint64_t(cache.lineBytes) * cache.ways;
    const std::uint64_t sets = cache.sizeBytes / setBytes;
    if (cache.sizeBytes % setBytes != 0 || sets == 0 || (sets & (sets - 1)) != 0)
        fail(where, "cache.sizeBytes",
             "must be a power-of-two multiple of cache.lineBytes x cache.ways (" + std::to_string(setBytes) +
                 " bytes) (got " + std::to_string(cache.sizeBytes) + ")");
    const std::uint64_t l2SetBytes = std::uint64_t(l2.lineBytes) * l2.ways * l2.banks;
    const std::uint64_t l2Sets = l2.sizeBytes / l2SetBytes;
    if (l2.sizeBytes % l2SetBytes != 0 || l2Sets == 0 || (l2Sets & (l2Sets - 1)) != 0)
        fail(where, "l2.sizeBytes",
             "must be a power-of-two multiple of l2.lineBytes x l2.ways x l2.banks (" + std::to_string(l2SetBytes) +
                 " bytes) (got " + std::to_string(l2.sizeBytes) + ")");
    // The model's cache state, in lines (each core's node cache and the L2):
    // bounded, so that a configuration file cannot ask for gigabytes.
    const std::uint64_t lines =
        std::uint64_t(gpu.cores) * (cache.sizeBytes / cache.lineBytes) + l2.sizeBytes / l2.lineBytes;
    if (lines > kMaxModelCacheLines)
        fail(where, "cache.sizeBytes",
             "gpu.cores x cache.sizeBytes / cache.lineBytes + l2.sizeBytes / l2.lineBytes must be at most " +
                 std::to_string(kMaxModelCacheLines) + " cache lines in all (got " + std::to_string(lines) + ")");
    if (l2.mode == L2Mode::Cache && l2.hitLatency < l2.bankCycles)
        fail(where, "l2.hitLatency",
             "must be at least l2.bankCycles (" + std::to_string(l2.bankCycles) + ") in l2 mode cache (got " +
                 std::to_string(l2.hitLatency) + ")");
    if (cache.sectorBytes != 0 && (cache.sectorBytes >= cache.lineBytes || cache.lineBytes / cache.sectorBytes > 32))
        fail(where, "cache.sectorBytes",
             "must be smaller than cache.lineBytes (" + std::to_string(cache.lineBytes) +
                 "), at most 32 sectors a line, or 0 (got " + std::to_string(cache.sectorBytes) + ")");
    if (l2.mode == L2Mode::Cache && l2.lineBytes < cache.fillBytes())
        fail(where, "l2.lineBytes",
             "must be at least the node cache's fill unit (cache.sectorBytes, else cache.lineBytes: " +
                 std::to_string(cache.fillBytes()) + ") in l2 mode cache (got " + std::to_string(l2.lineBytes) + ")");
}

RtCoreConfig RtCoreConfig::fromJson(const nlohmann::json& json, const std::string& where) {
    RtCoreConfig config;
    config.applyJson(json, where);
    return config;
}

RtCoreConfig RtCoreConfig::loadFile(const std::filesystem::path& path) {
    const std::string where = path.string();
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(where, "cannot open RT-core configuration");
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (jsonNestingDepth(text) > kMaxJsonNesting)
        throw InputError(where, "JSON nested deeper than " + std::to_string(kMaxJsonNesting) + " levels");
    nlohmann::json json;
    try {
        json = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception& e) {  // parse_error, and out_of_range for numbers like 1e999
        throw InputError(where, std::string("invalid JSON: ") + e.what());
    }
    return fromJson(json, where);
}

void RtCoreConfig::applyJson(const nlohmann::json& json, const std::string& where) {
    if (!json.is_object()) throw InputError(where, "RT-core configuration must be a JSON object of sections");
    for (const auto& item : json.items()) {
        const std::string section = item.key();  // a named variable: lambdas below capture it
        const nlohmann::json& fields = item.value();
        // A file's documentation: its description and each number's source.
        if (section == "description") {
            if (!fields.is_string()) fail(where, section, "must be a string");
            continue;
        }
        if (section == "sources") {
            if (!fields.is_object())
                fail(where, section, "must be an object \"section.field\": \"where the value comes from\"");
            continue;
        }
        bool sectionExists = false;
        forEachSection([&](const char* name, auto, const auto&) { sectionExists = sectionExists || section == name; });
        if (!sectionExists) fail(where, section, "unknown section (known: " + knownSections() + ")");
        if (!fields.is_object()) fail(where, section, "must be an object of parameters");
        for (const auto& [field, value] : fields.items()) setField(*this, section, field, value, where);
    }
}

void RtCoreConfig::set(const std::string& assignment, const std::string& where) {
    // Step: split "section.field=value".
    const std::size_t eq = assignment.find('=');
    const std::size_t dot = assignment.find('.');
    if (eq == std::string::npos || dot == std::string::npos || dot > eq || dot == 0 || dot + 1 == eq)
        throw InputError(where, "expected section.field=value (got \"" + assignment + "\")");
    const std::string section = assignment.substr(0, dot);
    const std::string field = assignment.substr(dot + 1, eq - dot - 1);
    const std::string text = assignment.substr(eq + 1);
    if (text.empty()) fail(where, section + "." + field, "missing value");

    // Step: the value is JSON when it parses as JSON, a bare word otherwise.
    nlohmann::json value = nlohmann::json::parse(text, nullptr, false);
    if (value.is_discarded()) value = text;

    if (!setField(*this, section, field, value, where))
        fail(where, section + "." + field, "unknown section \"" + section + "\" (known: " + knownSections() + ")");
    const std::string key = section + "." + field;
    if (std::find(explicitKeys_.begin(), explicitKeys_.end(), key) == explicitKeys_.end()) explicitKeys_.push_back(key);
}

std::string RtCoreConfig::inertReason(const std::string& key, ConfigUse use) const {
    const std::string section = key.substr(0, key.find('.'));
    const bool builtinWithoutTreelets = scheduler.policy == "fifo" || scheduler.policy == "oldestFirst";
    if (l2.mode == L2Mode::Ideal && ((section == "l2" && key != "l2.mode") || section == "dram"))
        return "l2.mode is ideal (every access hits at the cost of the core's port alone; set l2.mode=cache to "
               "model the L2 and DRAM)";
    if (gpu.launch == LaunchMode::Tile && (key == "gpu.residentWarps" || key == "shader.nextTraceLatency"))
        return "gpu.launch is tile (every trace call is its own batch; launches are gpu.launch=launch)";
    if (use == ConfigUse::GpuCheckExport) {
        if (section == "shader")
            return "gpucheck-export runs no any-hit or intersection shader, and each selected ray is a thread of "
                   "its own: no ray waits on a shader";
        if (key == "gpu.launch" && gpu.launch == LaunchMode::Tile)
            return "gpucheck-export predicts one launch, one thread per selected ray, as the GPU check runs them";
    }
    if (gpu.cores == 1 && key == "gpu.dispatch") return "gpu.cores is 1 (every warp goes to the one core)";
    if (gpu.cores == 1 && key == "l2.serviceOrder")
        return "gpu.cores is 1 (the one core's port delivers its requests in the order it makes them, so both orders "
               "serve them alike)";
    if (key == "scheduler.treeletBytes" && builtinWithoutTreelets)
        return "scheduler.policy is " + scheduler.policy + " (only treelet and treeletPrefetch use treelets)";
    if (key == "scheduler.prefetchBytes" && (builtinWithoutTreelets || scheduler.policy == "treelet"))
        return "scheduler.policy is " + scheduler.policy + " (only treeletPrefetch prefetches)";
    return "";
}

void RtCoreConfig::checkExplicitKeys(const std::string& where, ConfigUse use) const {
    for (const std::string& key : explicitKeys_) {
        const std::string reason = inertReason(key, use);
        if (!reason.empty()) fail(where, key, "has no effect here: " + reason);
    }
}

RtCoreConfig RtCoreConfig::load(const std::string& nameOrPath) {
    const std::string name = nameOrPath.empty() ? std::string(kDefaultRtCorePreset) : nameOrPath;
    if (const char* text = rtcorePresetText(name)) {
        const nlohmann::json j = nlohmann::json::parse(text);  // built in and tested: valid
        return fromJson(j, "rtcore preset " + name);
    }
    const std::filesystem::path path(nameOrPath);
    if (!std::filesystem::exists(path) && path.extension() != ".json" && nameOrPath.find('/') == std::string::npos) {
        std::string names;
        for (const std::string& n : rtcorePresetNames()) names += (names.empty() ? "" : ", ") + n;
        throw InputError(nameOrPath, "neither an RT-core preset (" + names + ") nor a configuration file");
    }
    return loadFile(path);
}

nlohmann::json RtCoreConfig::toJson() const {
    nlohmann::json out = nlohmann::json::object();
    forEachSection([&](const char* name, auto member, const auto& table) {
        nlohmann::json& section = out[name];
        section = nlohmann::json::object();
        for (const auto& f : table.fields()) section[f.info.name] = f.read(this->*member);
    });
    return out;
}

nlohmann::json RtCoreConfig::describe() {
    nlohmann::json out = nlohmann::json::object();
    forEachSection([&](const char* name, auto, const auto& table) {
        for (const auto& f : table.fields()) {
            nlohmann::json d;
            d["description"] = f.info.description;
            d["default"] = f.info.defaultValue;
            if (const std::vector<nlohmann::json> allowed = allowedValues(f.info); !allowed.empty())
                d["allowed"] = allowed;
            else if (f.info.kind == ParamKind::Unsigned || f.info.kind == ParamKind::Real)
                d["range"] = {f.info.min, f.info.max};
            out[name][f.info.name] = std::move(d);
        }
    });
    return out;
}

}  // namespace rtlab::rtcore_sim
