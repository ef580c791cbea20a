#include <rtlab/study/report.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/plot.hpp>
#include <rtlab/study/metrics.hpp>
#include <rtlab/study/result_store.hpp>
#include <rtlab/study/study.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

namespace rtlab::study {

namespace fs = std::filesystem;
using nlohmann::json;

std::string base64(const std::string& bytes) {
    static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    out.reserve((bytes.size() + 2) / 3 * 4);
    std::size_t i = 0;
    for (; i + 2 < bytes.size(); i += 3) {
        const unsigned v =
            (unsigned char)bytes[i] << 16 | (unsigned char)bytes[i + 1] << 8 | (unsigned char)bytes[i + 2];
        out += table[v >> 18 & 63];
        out += table[v >> 12 & 63];
        out += table[v >> 6 & 63];
        out += table[v & 63];
    }
    if (i + 1 == bytes.size()) {
        const unsigned v = (unsigned char)bytes[i] << 16;
        out += table[v >> 18 & 63];
        out += table[v >> 12 & 63];
        out += "==";
    } else if (i + 2 == bytes.size()) {
        const unsigned v = (unsigned char)bytes[i] << 16 | (unsigned char)bytes[i + 1] << 8;
        out += table[v >> 18 & 63];
        out += table[v >> 12 & 63];
        out += table[v >> 6 & 63];
        out += '=';
    }
    return out;
}

std::string htmlEscape(const std::string& text) {
    std::string out;
    for (char c : text) {
        switch (c) {
            case '&': out += "&amp;"; break;
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '"': out += "&quot;"; break;
            default: out += c;
        }
    }
    return out;
}

namespace {

std::string readBinary(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

// A cell: integers as they are, other numbers with 4 significant digits.
std::string formatValue(const json& v) {
    if (v.is_null()) return "";
    if (v.is_string()) return v.get<std::string>();
    if (v.is_number_float()) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.4g", v.get<double>());
        return buf;
    }
    return v.dump();
}

std::string fileSafe(std::string s) {
    for (char& c : s)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '.') c = '_';
    return s;
}

const json& valueOf(const json& row, const MetricInfo& m) {
    static const json null;
    const json& group = row.contains(m.timing ? "timing" : "metrics") ? row[m.timing ? "timing" : "metrics"] : null;
    return group.is_object() && group.contains(m.name) ? group[m.name] : null;
}

struct Plot {
    std::string parameter, metric, caption;
    fs::path png;
};

// One plot: metric against `parameter`, one series per workload and setting
// of the other swept parameters. Categorical values are placed at 1, 2, ...
Plot drawPlot(const fs::path& dir, const std::vector<json>& rows, const std::vector<std::string>& parameters,
              const std::string& parameter, const MetricInfo& metric, const std::vector<json>& valueOrder) {
    bool numeric = true;
    for (const json& v : valueOrder) numeric = numeric && v.is_number() && v.get<double>() > 0.0;
    const auto xOf = [&](const json& v) -> double {
        if (numeric) return v.get<double>();
        for (std::size_t i = 0; i < valueOrder.size(); ++i)
            if (valueOrder[i] == v) return double(i + 1);
        return 0.0;
    };
    std::map<std::string, std::vector<std::pair<double, double>>> series;  // name -> (x, y)
    std::vector<std::string> seriesOrder;
    for (const json& row : rows) {
        const json overrides = row.value("overrides", json::object());
        if (!overrides.contains(parameter)) continue;
        const json& y = valueOf(row, metric);
        if (!y.is_number()) continue;
        std::string name = row.value("workload", "");
        for (const std::string& q : parameters)
            if (q != parameter && overrides.contains(q)) name += ", " + q + "=" + formatValue(overrides[q]);
        if (!series.count(name)) seriesOrder.push_back(name);
        series[name].emplace_back(xOf(overrides[parameter]), y.get<double>());
    }
    std::vector<PlotSeries> plotted;
    for (const std::string& name : seriesOrder) {
        auto points = series[name];
        std::stable_sort(points.begin(), points.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
        PlotSeries s;
        s.name = name;
        for (const auto& [x, y] : points) {
            s.x.push_back(x);
            s.y.push_back(y);
        }
        plotted.push_back(std::move(s));
    }
    Plot plot;
    plot.parameter = parameter;
    plot.metric = metric.name;
    PlotOptions options;
    options.width = 900;
    options.height = 560;
    options.title = metric.name + " vs " + parameter;
    options.xLabel = parameter + (numeric ? "" : " (category index)");
    options.yLabel = metric.name;
    plot.png = dir / "plots" / (fileSafe(metric.name) + "-vs-" + fileSafe(parameter) + ".png");
    fs::create_directories(plot.png.parent_path());
    const PlotReport report = writeLogLogPlot(plot.png, plotted, options);
    plot.caption = metric.name + " (" + metric.description + ") against " + parameter + ", log-log; " +
                   std::to_string(plotted.size()) + " line(s)";
    if (!numeric) {
        plot.caption += "; x is the category index:";
        for (std::size_t i = 0; i < valueOrder.size(); ++i)
            plot.caption +=
                std::string(i ? "," : "") + " " + std::to_string(i + 1) + " = " + formatValue(valueOrder[i]);
    }
    plot.caption += "; lines:";
    for (std::size_t i = 0; i < seriesOrder.size(); ++i) plot.caption += (i ? "; " : " ") + seriesOrder[i];
    if (report.pointsSkipped > 0)
        plot.caption += "; " + std::to_string(report.pointsSkipped) + " point(s) not drawable on log axes (zero)";
    return plot;
}

const char* kStyle = R"(body{font-family:sans-serif;margin:2em;color:#222;max-width:1200px}
h1{font-size:1.5em}h2{font-size:1.2em;margin-top:1.6em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;font-size:0.85em}td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}
th{background:#eee}td.l,th.l{text-align:left}pre{background:#f6f6f6;padding:0.6em;overflow-x:auto;font-size:0.85em}
figure{margin:1em 0}figcaption{font-size:0.85em;color:#555;max-width:900px}img{border:1px solid #ddd})";

}  // namespace

ReportSummary writeReport(const fs::path& dir) {
    const json record = readStudyRecord(dir);
    const std::string recordPath = (dir / "study.json").string();
    const Study study = parseStudy(record.at("study"), recordPath, false);
    const std::vector<Point> points = expandPoints(study);
    const std::vector<std::string> parameters = sweptParameters(study);
    const std::vector<json> rows = readRows(dir);
    const std::string studyFile = record.value("studyFile", std::string("STUDY.json"));

    ReportSummary summary;
    summary.rows = rows.size();
    summary.points = points.size();
    std::ostringstream h;
    h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>rtlab study: "
      << htmlEscape(studyFile) << "</title>\n<style>" << kStyle << "</style></head><body>\n";
    h << "<h1>rtlab study: " << htmlEscape(studyFile) << "</h1>\n";
    h << "<p>" << rows.size() << " of " << points.size() << " point(s) complete"
      << (rows.size() < points.size() ? " (rerun the sweep command below to finish the rest)" : "") << "; "
      << study.workloads.size() << " workload(s) x "
      << (study.workloads.empty() ? 0 : points.size() / study.workloads.size())
      << " configuration(s). Study fingerprint <code>" << htmlEscape(record.value("fingerprint", ""))
      << "</code>.</p>\n";

    // Step: the parameter space.
    h << "<h2>Parameter space</h2>\n<table><tr><th class=\"l\">what</th><th class=\"l\">values</th></tr>\n";
    h << "<tr><td class=\"l\">workloads</td><td class=\"l\">";
    for (std::size_t i = 0; i < study.workloads.size(); ++i)
        h << (i ? ", " : "") << htmlEscape(study.workloads[i].label());
    h << "</td></tr>\n";
    for (const auto& [key, values] : study.grid) {
        h << "<tr><td class=\"l\">grid: " << htmlEscape(key) << "</td><td class=\"l\">";
        for (std::size_t i = 0; i < values.size(); ++i) h << (i ? ", " : "") << htmlEscape(formatValue(values[i]));
        h << "</td></tr>\n";
    }
    for (std::size_t i = 0; i < study.list.size(); ++i) {
        h << "<tr><td class=\"l\">list[" << i << "]</td><td class=\"l\">";
        for (std::size_t k = 0; k < study.list[i].size(); ++k)
            h << (k ? ", " : "") << htmlEscape(study.list[i][k].assignment());
        h << "</td></tr>\n";
    }
    for (const Override& o : study.base)
        h << "<tr><td class=\"l\">base (every point)</td><td class=\"l\">" << htmlEscape(o.assignment())
          << "</td></tr>\n";
    h << "<tr><td class=\"l\">render</td><td class=\"l\">" << htmlEscape(studyRenderJson(study.render).dump())
      << "</td></tr>\n";
    h << "</table>\n";

    // Step: one plot per swept parameter and plotted metric that has values.
    h << "<h2>Plots</h2>\n";
    bool anyPlot = false;
    for (const std::string& parameter : parameters) {
        std::vector<json> order;  // the parameter's values in study order
        for (const auto& [key, values] : study.grid)
            if (key == parameter) order = values;
        for (const OverrideSet& set : study.list)
            for (const Override& o : set)
                if (o.key == parameter && std::find(order.begin(), order.end(), o.value) == order.end())
                    order.push_back(o.value);
        for (const MetricInfo& metric : metricList()) {
            if (!metric.plotted) continue;
            const bool hasValues = std::any_of(rows.begin(), rows.end(), [&](const json& r) {
                return valueOf(r, metric).is_number() && r.value("overrides", json::object()).contains(parameter);
            });
            if (!hasValues) continue;
            const Plot plot = drawPlot(dir, rows, parameters, parameter, metric, order);
            summary.plots.push_back(plot.png);
            anyPlot = true;
            h << "<figure><img alt=\"" << htmlEscape(plot.metric + " vs " + plot.parameter)
              << "\" src=\"data:image/png;base64," << base64(readBinary(plot.png)) << "\"><figcaption>"
              << htmlEscape(plot.caption) << "</figcaption></figure>\n";
        }
    }
    if (!anyPlot) h << "<p>No plot: the study sweeps no parameter, or no point has RT-core metrics yet.</p>\n";

    // Step: every point.
    h << "<h2>Points</h2>\n<table><tr><th class=\"l\">id</th><th class=\"l\">workload</th>";
    for (const std::string& p : parameters) h << "<th>" << htmlEscape(p) << "</th>";
    for (const MetricInfo& m : metricList())
        h << "<th title=\"" << htmlEscape(m.description) << "\">" << htmlEscape(m.name) << "</th>";
    h << "</tr>\n";
    for (const json& row : rows) {
        const json overrides = row.value("overrides", json::object());
        h << "<tr><td class=\"l\">" << htmlEscape(row.value("id", "")) << "</td><td class=\"l\">"
          << htmlEscape(row.value("workload", "")) << "</td>";
        for (const std::string& p : parameters)
            h << "<td>" << htmlEscape(formatValue(overrides.value(p, json(nullptr)))) << "</td>";
        for (const MetricInfo& m : metricList()) h << "<td>" << htmlEscape(formatValue(valueOf(row, m))) << "</td>";
        h << "</tr>\n";
    }
    h << "</table>\n<p>Metrics (docs/studies.md):</p><ul>\n";
    for (const MetricInfo& m : metricList())
        h << "<li><b>" << htmlEscape(m.name) << "</b>: " << htmlEscape(m.description)
          << (m.timing ? " (timing: varies run to run)" : "") << "</li>\n";
    h << "</ul>\n";

    // Step: the resolved base configuration.
    h << "<h2>Base configuration</h2>\n";
    if (record.contains("baseConfig"))
        h << "<p>The RT-core configuration every point starts from (defaults, render.rtcoreConfig, base); each "
             "point then applies its own overrides.</p>\n<pre>"
          << htmlEscape(record["baseConfig"].dump(2)) << "</pre>\n";
    else h << "<p>Back end " << htmlEscape(study.render.backend) << ": no RT-core configuration.</p>\n";

    // Step: how to reproduce it.
    const std::string out = dir.string();
    h << "<h2>Reproduce</h2>\n<p>The study file (canonical form; save it as " << htmlEscape(studyFile)
      << "):</p>\n<pre>" << htmlEscape(study.toJson().dump(2)) << "</pre>\n<p>Then:</p>\n<pre>"
      << htmlEscape(shellCommand({"rtlab", "sweep", studyFile, "--out", out})) << "\n"
      << htmlEscape(shellCommand({"rtlab", "report", out})) << "</pre>\n";
    h << "<details><summary>One point at a time (" << points.size() << " rtlab render commands)</summary><pre>";
    for (const Point& p : points) {
        std::vector<std::string> args = renderArguments(study, p, "out/" + p.id, 0);
        args.insert(args.begin(), "rtlab");
        h << htmlEscape(shellCommand(args)) << "\n";
    }
    h << "</pre></details>\n</body></html>\n";

    summary.html = dir / "report.html";
    writeTextFileAtomically(summary.html, h.str());
    return summary;
}

}  // namespace rtlab::study
