#pragma once
// What matters first in a study's results (docs/studies.md, "Summary"): per
// workload the best and the worst configuration by each objective metric,
// and per swept parameter its effect: the metric at each of its values
// relative to its first value, over every pair of points that differ in that
// parameter alone (same workload, same other overrides), as a geometric mean
// with its range. `rtlab report` puts it at the top of report.html and writes
// it as DIR/summary.json.
#include <rtlab/study/study.hpp>

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <vector>

namespace rtlab::study {

struct RankedPoint {
    std::string id;             // "p0003"
    std::string configuration;  // "cache.sizeBytes=4096, traversal.units=2" ("base" when none)
    double value = 0.0;
};

struct WorkloadBest {
    std::string workload;  // Workload::label()
    std::size_t points = 0;
    RankedPoint best, worst;
};

struct ValueEffect {
    nlohmann::json value;                 // the parameter's value
    std::size_t pairs = 0;                // point pairs compared (0: none differ in this parameter alone)
    std::optional<double> geometricMean;  // metric(value) / metric(first value)
    std::optional<double> min, max;
};

struct ParameterEffect {
    std::string parameter;
    nlohmann::json baseValue;  // the first value in study order
    std::vector<ValueEffect> values;
};

struct ObjectiveSummary {
    std::string metric;
    bool higherIsBetter = false;
    std::vector<WorkloadBest> workloads;
    std::vector<ParameterEffect> parameters;
};

struct StudySummary {
    std::vector<ObjectiveSummary> objectives;
    nlohmann::json toJson() const;
};

// From the study and its result rows (results.jsonl); rows without the
// metric are left out of its objective.
StudySummary summarizeStudy(const Study& study, const std::vector<nlohmann::json>& rows);

// A swept parameter's values in study order: the grid's, then the list's first appearances.
std::vector<nlohmann::json> parameterValuesInOrder(const Study& study, const std::string& parameter);

// A row's overrides as "k=v, k=v" in the study's parameter order ("base" when none).
std::string configurationText(const nlohmann::json& overrides, const std::vector<std::string>& parameters);

}  // namespace rtlab::study
