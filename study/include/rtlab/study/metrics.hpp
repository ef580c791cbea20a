#pragma once
// The metrics of a point, read from its stats.json (docs/studies.md). This
// table is the one place that lists them: the result rows, the CSV columns
// and the report's plots all follow it.
//
// Extraction is tolerant: a metric whose statistics are absent (the embree
// back end has no cycles; an RT-core model without an L2 has no L2 hit rate)
// is null, not an error. Counters are summed over the frames; rates are
// derived from the sums.
#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace rtlab::study {

struct MetricInfo {
    std::string name;         // key in results.jsonl "metrics", CSV column
    std::string description;  // one line, for docs and the report
    bool timing = false;      // varies run to run (excluded when rows are compared)
    bool plotted = false;     // the report draws it against each swept parameter
    // For a study's objective: rates and hit rates; counts and times are lower-better.
    bool higherIsBetter = false;
    std::string unit;  // the plots' axis label: "cycles", "bytes", "fraction", ...
};

// Every metric, in column order.
const std::vector<MetricInfo>& metricList();

// {"name": number or null, ...} for every metric of metricList() that is not
// a timing metric, from a render's stats.json tree.
nlohmann::json extractMetrics(const nlohmann::json& stats);
// The timing metrics ({"renderMs": ...}); wallSeconds is added by the sweep.
nlohmann::json extractTimings(const nlohmann::json& stats);

}  // namespace rtlab::study
