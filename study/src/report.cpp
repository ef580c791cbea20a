#include <rtlab/study/report.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/core/plot.hpp>
#include <rtlab/core/process.hpp>
#include <rtlab/study/metrics.hpp>
#include <rtlab/study/result_store.hpp>
#include <rtlab/study/study.hpp>
#include <rtlab/study/summary.hpp>

#include <nlohmann/json.hpp>

#include <cerrno>
#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

namespace rtlab::study {

namespace fs = std::filesystem;
using nlohmann::json;

std::string htmlEscape(const std::string& text) { return xmlEscape(text); }

namespace {

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
    fs::path png, svg, pdf, csv;  // pdf empty when it could not be written
    std::string svgText;
    std::size_t rowsDrawn = 0;
};

// DIR/plots/NAME.pdf from NAME.svg through rsvg-convert (librsvg: the SVG's
// fonts embedded as TrueType subsets), written to a temporary name and
// renamed. False, with `why`, when the tool is missing or fails.
bool convertSvgToPdf(const fs::path& svg, const fs::path& pdf, std::string& why) {
    const fs::path tmp = pdf.string() + ".tmp";
    const pid_t pid = spawnProcess({"rsvg-convert", "-f", "pdf", "-o", tmp.string(), svg.string()});
    if (pid < 0) {
        why = "rsvg-convert not found (scripts/install-deps.sh installs librsvg2-bin)";
        return false;
    }
    const int status = waitForProcess(pid);
    std::error_code ec;
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0 || !fs::exists(tmp, ec)) {
        fs::remove(tmp, ec);
        why = WIFEXITED(status) && WEXITSTATUS(status) == 127
                  ? "rsvg-convert not found (scripts/install-deps.sh installs librsvg2-bin)"
                  : "rsvg-convert failed on " + svg.string();
        return false;
    }
    fs::rename(tmp, pdf, ec);
    if (ec) {
        why = "cannot write " + pdf.string() + ": " + ec.message();
        return false;
    }
    return true;
}

std::string csvCell(const std::string& s) {
    if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
    std::string out = "\"";
    for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
    return out + "\"";
}

// One plot: metric against `parameter`, one series per workload and setting
// of the other swept parameters. Categorical values are placed at 1, 2, ...
Plot drawPlot(const fs::path& dir, const std::vector<json>& rows, const std::vector<std::string>& parameters,
              const std::string& parameter, const MetricInfo& metric, const std::vector<json>& valueOrder,
              const std::string& baseText, std::string& pdfProblem) {
    bool numeric = true;
    for (const json& v : valueOrder) numeric = numeric && v.is_number() && v.get<double>() > 0.0;
    const auto xOf = [&](const json& v) -> double {
        if (numeric) return v.get<double>();
        for (std::size_t i = 0; i < valueOrder.size(); ++i)
            if (valueOrder[i] == v) return double(i + 1);
        return 0.0;
    };
    struct Drawn {
        double x, y;
        std::string title;
    };
    std::map<std::string, std::vector<Drawn>> series;  // name -> points
    std::vector<std::string> seriesOrder;
    std::string csv = "id,workload";
    for (const std::string& q : parameters) csv += "," + csvCell(q);
    csv += "," + csvCell(metric.name) + "\n";
    Plot plot;
    for (const json& row : rows) {
        const json overrides = row.value("overrides", json::object());
        if (!overrides.contains(parameter)) continue;
        const json& y = valueOf(row, metric);
        if (!y.is_number()) continue;
        std::string name = row.value("workload", "");
        for (const std::string& q : parameters)
            if (q != parameter && overrides.contains(q)) name += ", " + q + "=" + formatValue(overrides[q]);
        if (!series.count(name)) seriesOrder.push_back(name);
        // The point's whole configuration, for its hover title.
        const std::string title = row.value("id", "") + ": " + row.value("workload", "") + "; " +
                                  configurationText(overrides, parameters) + baseText + "; " + metric.name + " = " +
                                  formatValue(y);
        series[name].push_back({xOf(overrides[parameter]), y.get<double>(), title});
        csv += csvCell(row.value("id", "")) + "," + csvCell(row.value("workload", ""));
        // Full precision in the data (the page rounds to 4 digits, the CSV does not).
        const auto exact = [](const json& v) {
            return v.is_null() ? std::string() : v.is_string() ? v.get<std::string>() : v.dump();
        };
        for (const std::string& q : parameters) csv += "," + csvCell(exact(overrides.value(q, json(nullptr))));
        csv += "," + exact(y) + "\n";
        ++plot.rowsDrawn;
    }
    std::vector<PlotSeries> plotted;
    SvgPlotExtras extras;
    for (const std::string& name : seriesOrder) {
        auto points = series[name];
        std::stable_sort(points.begin(), points.end(), [](const Drawn& a, const Drawn& b) { return a.x < b.x; });
        PlotSeries s;
        s.name = name;
        extras.pointTitles.emplace_back();
        for (const Drawn& d : points) {
            s.x.push_back(d.x);
            s.y.push_back(d.y);
            extras.pointTitles.back().push_back(d.title);
        }
        plotted.push_back(std::move(s));
    }
    plot.parameter = parameter;
    plot.metric = metric.name;
    PlotOptions options;
    options.width = 900;
    options.height = 560;
    options.title = metric.name + " vs " + parameter;
    options.xLabel = parameter + (numeric ? "" : " (category index)");
    options.yLabel = metric.name + " (" + metric.unit + ")";
    const std::string stem = fileSafe(metric.name) + "-vs-" + fileSafe(parameter);
    plot.png = dir / "plots" / (stem + ".png");
    fs::create_directories(plot.png.parent_path());
    const PlotReport report = writeLogLogPlot(plot.png, plotted, options);
    // Step: the same plot for a paper: SVG (categories named on the axis),
    // PDF with the font embedded, and the rows it was drawn from.
    PlotOptions vector = options;
    vector.title.clear();  // a paper's caption says it
    vector.xLabel = parameter;
    if (!numeric)
        for (const json& v : valueOrder) extras.xCategories.push_back(formatValue(v));
    plot.svgText = renderLogLogPlotSvg(plotted, vector, extras);
    plot.svg = dir / "plots" / (stem + ".svg");
    writeTextFileAtomically(plot.svg, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n" + plot.svgText);
    plot.csv = dir / "plots" / (stem + ".csv");
    writeTextFileAtomically(plot.csv, csv);
    const fs::path pdf = dir / "plots" / (stem + ".pdf");
    if (pdfProblem.empty() && convertSvgToPdf(plot.svg, pdf, pdfProblem)) plot.pdf = pdf;
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
figure{margin:1em 0}figcaption{font-size:0.85em;color:#555;max-width:900px}img{border:1px solid #ddd}
figure svg{width:504px;height:auto;border:1px solid #ddd}td.best{background:#e6f4e6}td.worst{background:#f8e6e6})";

// The summary's value cells: 4 significant digits; a ratio as "x1.234".
std::string ratioText(const std::optional<double>& r) {
    if (!r) return "-";
    char buf[32];
    std::snprintf(buf, sizeof buf, "x%.4g", *r);
    return buf;
}

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

    // Step: the summary first (also DIR/summary.json).
    const StudySummary digest = summarizeStudy(study, rows);
    writeTextFileAtomically(dir / "summary.json", digest.toJson().dump(2) + "\n");
    summary.summaryJson = dir / "summary.json";
    h << "<h2 id=\"summary\">Summary</h2>\n";
    for (const ObjectiveSummary& o : digest.objectives) {
        h << "<p>By <b>" << htmlEscape(o.metric) << "</b> (" << (o.higherIsBetter ? "higher" : "lower")
          << " is better; the study's <code>objective</code>):</p>\n";
        h << "<table class=\"summary\"><tr><th class=\"l\">workload</th><th>points</th><th class=\"l\">best</th><th>"
          << htmlEscape(o.metric) << "</th><th class=\"l\">worst</th><th>" << htmlEscape(o.metric)
          << "</th><th>worst / best</th></tr>\n";
        for (const WorkloadBest& w : o.workloads) {
            std::optional<double> spread;
            if (w.best.value != 0.0) spread = w.worst.value / w.best.value;
            h << "<tr><td class=\"l\">" << htmlEscape(w.workload) << "</td><td>" << w.points
              << "</td><td class=\"l best\">" << htmlEscape(w.best.id + ": " + w.best.configuration) << "</td><td>"
              << htmlEscape(formatValue(json(w.best.value))) << "</td><td class=\"l worst\">"
              << htmlEscape(w.worst.id + ": " + w.worst.configuration) << "</td><td>"
              << htmlEscape(formatValue(json(w.worst.value))) << "</td><td>" << htmlEscape(ratioText(spread))
              << "</td></tr>\n";
        }
        h << "</table>\n";
        if (!o.parameters.empty()) {
            h << "<p>Each swept parameter's effect on " << htmlEscape(o.metric)
              << ": at each value, relative to the parameter's first value, over the pairs of points that differ in "
                 "it alone (same workload, same other settings); geometric mean and range across them.</p>\n"
              << "<table class=\"effects\"><tr><th class=\"l\">parameter</th><th class=\"l\">value</th><th>pairs</th>"
                 "<th>relative (geometric mean)</th><th>min</th><th>max</th></tr>\n";
            for (const ParameterEffect& p : o.parameters)
                for (const ValueEffect& v : p.values)
                    h << "<tr><td class=\"l\">" << htmlEscape(p.parameter) << "</td><td class=\"l\">"
                      << htmlEscape(formatValue(v.value)) << (v.value == p.baseValue ? " (base)" : "") << "</td><td>"
                      << v.pairs << "</td><td>" << htmlEscape(ratioText(v.geometricMean)) << "</td><td>"
                      << htmlEscape(ratioText(v.min)) << "</td><td>" << htmlEscape(ratioText(v.max)) << "</td></tr>\n";
            h << "</table>\n";
        }
    }
    if (digest.objectives.empty() || std::all_of(digest.objectives.begin(), digest.objectives.end(),
                                                 [](const ObjectiveSummary& o) { return o.workloads.empty(); }))
        h << "<p>No point has the objective's metric yet.</p>\n";

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
    h << "<h2>Plots</h2>\n<p>Hover over a point for its id and whole configuration. Each plot is also in "
         "<code>plots/</code> as PDF (fonts embedded) and SVG (text as text) for a paper, as PNG, and as the CSV "
         "of the rows it shows.</p>\n";
    bool anyPlot = false;
    std::string baseText, pdfProblem;
    for (const Override& o : study.base) baseText += (baseText.empty() ? " (every point: " : ", ") + o.assignment();
    if (!baseText.empty()) baseText += ")";
    for (const std::string& parameter : parameters) {
        const std::vector<json> order = parameterValuesInOrder(study, parameter);
        for (const MetricInfo& metric : metricList()) {
            if (!metric.plotted) continue;
            const bool hasValues = std::any_of(rows.begin(), rows.end(), [&](const json& r) {
                return valueOf(r, metric).is_number() && r.value("overrides", json::object()).contains(parameter);
            });
            if (!hasValues) continue;
            const Plot plot = drawPlot(dir, rows, parameters, parameter, metric, order, baseText, pdfProblem);
            summary.plots.push_back(plot.png);
            summary.svgs.push_back(plot.svg);
            if (!plot.pdf.empty()) summary.pdfs.push_back(plot.pdf);
            anyPlot = true;
            const auto link = [&](const fs::path& file, const std::string& label) {
                return "<a href=\"" + htmlEscape(fs::relative(file, dir).generic_string()) + "\">" + label + "</a>";
            };
            h << "<figure>" << plot.svgText << "<figcaption>" << htmlEscape(plot.caption) << ". "
              << link(plot.csv, "Data: the " + std::to_string(plot.rowsDrawn) + " result row(s) drawn (CSV)") << "; "
              << (plot.pdf.empty() ? std::string("PDF not written") : link(plot.pdf, "PDF")) << "; "
              << link(plot.svg, "SVG") << "; " << link(plot.png, "PNG") << ".</figcaption></figure>\n";
        }
    }
    if (!anyPlot) h << "<p>No plot: the study sweeps no parameter, or no point has RT-core metrics yet.</p>\n";
    summary.pdfProblem = pdfProblem;

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
