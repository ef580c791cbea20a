// The study summary (summary.hpp): best and worst configuration per workload,
// each swept parameter's effect relative to its first value.
#include <rtlab/study/summary.hpp>

#include <rtlab/study/metrics.hpp>

#include <algorithm>
#include <cmath>
#include <map>

namespace rtlab::study {

using nlohmann::json;

namespace {

std::optional<double> metricOf(const json& row, const MetricInfo& m) {
    const char* group = m.timing ? "timing" : "metrics";
    if (!row.contains(group) || !row[group].is_object() || !row[group].contains(m.name)) return std::nullopt;
    const json& v = row[group][m.name];
    if (!v.is_number()) return std::nullopt;
    const double d = v.get<double>();
    return std::isfinite(d) ? std::optional<double>(d) : std::nullopt;
}

}  // namespace

std::vector<json> parameterValuesInOrder(const Study& study, const std::string& parameter) {
    std::vector<json> order;
    for (const auto& [key, values] : study.grid)
        if (key == parameter) order = values;
    for (const OverrideSet& set : study.list)
        for (const Override& o : set)
            if (o.key == parameter && std::find(order.begin(), order.end(), o.value) == order.end())
                order.push_back(o.value);
    return order;
}

std::string configurationText(const json& overrides, const std::vector<std::string>& parameters) {
    std::string text;
    for (const std::string& p : parameters)
        if (overrides.contains(p))
            text += (text.empty() ? "" : ", ") + p + "=" +
                    (overrides[p].is_string() ? overrides[p].get<std::string>() : overrides[p].dump());
    return text.empty() ? "base" : text;
}

StudySummary summarizeStudy(const Study& study, const std::vector<json>& rows) {
    const std::vector<std::string> parameters = sweptParameters(study);
    StudySummary summary;
    for (const std::string& name : study.objectives) {
        const auto metric =
            std::find_if(metricList().begin(), metricList().end(), [&](const MetricInfo& m) { return m.name == name; });
        if (metric == metricList().end()) continue;  // parseStudy refuses unknown names
        ObjectiveSummary o;
        o.metric = name;
        o.higherIsBetter = metric->higherIsBetter;
        const auto better = [&](double a, double b) { return o.higherIsBetter ? a > b : a < b; };
        // Step: per workload, in study order, the best and worst point.
        for (const Workload& w : study.workloads) {
            WorkloadBest wb;
            wb.workload = w.label();
            for (const json& row : rows) {
                if (row.value("workload", "") != wb.workload) continue;
                const std::optional<double> v = metricOf(row, *metric);
                if (!v) continue;
                const RankedPoint p{row.value("id", ""),
                                    configurationText(row.value("overrides", json::object()), parameters), *v};
                if (wb.points == 0 || better(*v, wb.best.value)) wb.best = p;
                if (wb.points == 0 || better(wb.worst.value, *v)) wb.worst = p;
                ++wb.points;
            }
            if (wb.points > 0) o.workloads.push_back(wb);
        }
        // Step: per parameter and value, ratios against the first value over
        // pairs of points equal in everything else.
        for (const std::string& parameter : parameters) {
            ParameterEffect e;
            e.parameter = parameter;
            const std::vector<json> order = parameterValuesInOrder(study, parameter);
            if (order.empty()) continue;
            e.baseValue = order.front();
            std::map<std::string, double> baseOf;  // workload + other overrides -> metric at the first value
            const auto keyOf = [&](const json& row) {
                json others = row.value("overrides", json::object());
                others.erase(parameter);
                return row.value("workload", "") + "\n" + others.dump();
            };
            for (const json& row : rows) {
                const json overrides = row.value("overrides", json::object());
                const std::optional<double> v = metricOf(row, *metric);
                if (v && overrides.contains(parameter) && overrides[parameter] == e.baseValue) baseOf[keyOf(row)] = *v;
            }
            for (const json& value : order) {
                ValueEffect ve;
                ve.value = value;
                double logSum = 0.0;
                for (const json& row : rows) {
                    const json overrides = row.value("overrides", json::object());
                    if (!overrides.contains(parameter) || overrides[parameter] != value) continue;
                    const std::optional<double> v = metricOf(row, *metric);
                    const auto base = baseOf.find(keyOf(row));
                    if (!v || base == baseOf.end() || !(base->second > 0.0) || !(*v > 0.0)) continue;
                    const double r = *v / base->second;
                    logSum += std::log(r);
                    ve.min = ve.min ? std::min(*ve.min, r) : r;
                    ve.max = ve.max ? std::max(*ve.max, r) : r;
                    ++ve.pairs;
                }
                if (ve.pairs > 0) ve.geometricMean = std::exp(logSum / double(ve.pairs));
                e.values.push_back(ve);
            }
            o.parameters.push_back(std::move(e));
        }
        summary.objectives.push_back(std::move(o));
    }
    return summary;
}

json StudySummary::toJson() const {
    const auto optional = [](const std::optional<double>& v) { return v ? json(*v) : json(nullptr); };
    json j = {{"objectives", json::array()}};
    for (const ObjectiveSummary& o : objectives) {
        json oj = {{"metric", o.metric},
                   {"better", o.higherIsBetter ? "higher" : "lower"},
                   {"workloads", json::array()},
                   {"parameters", json::array()}};
        for (const WorkloadBest& w : o.workloads)
            oj["workloads"].push_back(
                {{"workload", w.workload},
                 {"points", w.points},
                 {"best", {{"id", w.best.id}, {"configuration", w.best.configuration}, {"value", w.best.value}}},
                 {"worst", {{"id", w.worst.id}, {"configuration", w.worst.configuration}, {"value", w.worst.value}}}});
        for (const ParameterEffect& p : o.parameters) {
            json pj = {{"parameter", p.parameter}, {"baseValue", p.baseValue}, {"values", json::array()}};
            for (const ValueEffect& v : p.values)
                pj["values"].push_back({{"value", v.value},
                                        {"pairs", v.pairs},
                                        {"relativeGeometricMean", optional(v.geometricMean)},
                                        {"relativeMin", optional(v.min)},
                                        {"relativeMax", optional(v.max)}});
            oj["parameters"].push_back(std::move(pj));
        }
        j["objectives"].push_back(std::move(oj));
    }
    return j;
}

}  // namespace rtlab::study
