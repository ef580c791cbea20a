#include <rtlab/study/metrics.hpp>

#include <cmath>
#include <cstdint>
#include <functional>
#include <optional>

namespace rtlab::study {

namespace {

using nlohmann::json;
using Value = std::optional<double>;

// Σ over the frames of the number at `pointer`; nothing when a frame lacks it.
Value sumOverFrames(const json& stats, const char* pointer) {
    if (!stats.contains("frames") || !stats["frames"].is_array() || stats["frames"].empty()) return std::nullopt;
    const json::json_pointer p(pointer);
    double sum = 0.0;
    for (const json& frame : stats["frames"]) {
        if (!frame.contains(p) || !frame.at(p).is_number()) return std::nullopt;
        sum += frame.at(p).get<double>();
    }
    return sum;
}

Value ratio(Value a, Value b) {
    if (!a || !b || *b == 0.0) return std::nullopt;
    return *a / *b;
}

Value add(Value a, Value b) {
    if (!a) return b;
    if (!b) return a;
    return *a + *b;
}

struct Metric {
    MetricInfo info;
    std::function<Value(const json&)> read;  // empty for wallSeconds (the sweep measures it)
};

const std::vector<Metric>& metrics() {
    static const std::vector<Metric> table = {
        {{"raysTraced", "rays traced by the pipeline, every ray type, summed over frames", false, false, false, "rays"},
         [](const json& s) -> Value {
             if (!s.contains("frames") || !s["frames"].is_array() || s["frames"].empty()) return std::nullopt;
             double sum = 0.0;
             for (const json& f : s["frames"]) {
                 if (!f.contains("rays") || !f["rays"].is_object()) return std::nullopt;
                 for (const auto& [type, counts] : f["rays"].items())
                     if (counts.contains("traced") && counts["traced"].is_number())
                         sum += counts["traced"].get<double>();
             }
             return sum;
         }},
        {{"cycles", "RT-core model cycles (rtcore.frame.cycles), summed over frames", false, true, false, "cycles"},
         [](const json& s) { return sumOverFrames(s, "/rtcore/frame/cycles"); }},
        {{"raysPerCycle", "rays completed by the model per cycle (sum of rays / sum of cycles)", false, true, true,
          "rays per cycle"},
         [](const json& s) {
             return ratio(sumOverFrames(s, "/rtcore/frame/rays"), sumOverFrames(s, "/rtcore/frame/cycles"));
         }},
        {{"meanLatency", "mean ray latency in cycles, submission to result (rtcore.rays.latency)", false, true, false,
          "cycles"},
         [](const json& s) -> Value {
             if (!s.contains("frames") || !s["frames"].is_array() || s["frames"].empty()) return std::nullopt;
             double weighted = 0.0, count = 0.0;
             const json::json_pointer mean("/rtcore/rays/latency/mean"), n("/rtcore/rays/latency/count");
             for (const json& f : s["frames"]) {
                 if (!f.contains(mean) || !f.contains(n) || !f.at(mean).is_number() || !f.at(n).is_number())
                     return std::nullopt;
                 weighted += f.at(mean).get<double>() * f.at(n).get<double>();
                 count += f.at(n).get<double>();
             }
             return ratio(weighted, count);
         }},
        {{"cacheHitRate", "node cache (L1) hits / accesses (rtcore.cache)", false, true, true, "fraction of accesses"},
         [](const json& s) {
             return ratio(sumOverFrames(s, "/rtcore/cache/hits"), sumOverFrames(s, "/rtcore/cache/accesses"));
         }},
        {{"l2HitRate", "shared L2 hits / accesses (rtcore.l2), when the model has an L2", false, true, true,
          "fraction of accesses"},
         [](const json& s) {
             return ratio(sumOverFrames(s, "/rtcore/l2/hits"), sumOverFrames(s, "/rtcore/l2/accesses"));
         }},
        {{"memoryBytes", "bytes read and written behind the node cache (rtcore.memory)", false, false, false, "bytes"},
         [](const json& s) {
             return add(sumOverFrames(s, "/rtcore/memory/readBytes"), sumOverFrames(s, "/rtcore/memory/writeBytes"));
         }},
        {{"dramBytes", "DRAM bytes read and written (rtcore.dram), when the model has a DRAM section", false, true,
          false, "bytes"},
         [](const json& s) {
             return add(sumOverFrames(s, "/rtcore/dram/readBytes"), sumOverFrames(s, "/rtcore/dram/writeBytes"));
         }},
        {{"renderMs", "wall milliseconds of the frames' shading and tracing (timing.renderMs), summed", true, false,
          false, "ms"},
         [](const json& s) { return sumOverFrames(s, "/timing/renderMs"); }},
        {{"wallSeconds", "wall seconds of the point's whole `rtlab render` process", true, false, false, "s"}, {}},
    };
    return table;
}

// Whole numbers (cycles, bytes) as integers, so rows read as counts.
json toJson(Value v) {
    if (!v) return nullptr;
    if (std::isfinite(*v) && *v == std::floor(*v) && std::fabs(*v) < 9007199254740992.0)
        return static_cast<std::int64_t>(*v);
    return *v;
}

json extract(const json& stats, bool timing) {
    json out = json::object();
    for (const Metric& m : metrics())
        if (m.info.timing == timing && m.read) out[m.info.name] = toJson(m.read(stats));
    return out;
}

}  // namespace

const std::vector<MetricInfo>& metricList() {
    static const std::vector<MetricInfo> list = [] {
        std::vector<MetricInfo> l;
        for (const Metric& m : metrics()) l.push_back(m.info);
        return l;
    }();
    return list;
}

json extractMetrics(const json& stats) { return extract(stats, false); }
json extractTimings(const json& stats) { return extract(stats, true); }

}  // namespace rtlab::study
