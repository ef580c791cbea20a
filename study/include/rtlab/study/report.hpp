#pragma once
// `rtlab report DIR` (docs/studies.md): DIR/report.html, one self-contained
// page (no scripts, no external files; plots inline as base64 PNG): the
// parameter space, one plot per swept parameter and plotted metric (metric
// against the parameter's value, one line per workload and setting of the
// other parameters), every point's row, the resolved base configuration and
// the commands that reproduce the study. The plots are also written as
// DIR/plots/<metric>-vs-<parameter>.png.
#include <filesystem>
#include <string>
#include <vector>

namespace rtlab::study {

struct ReportSummary {
    std::filesystem::path html;
    std::vector<std::filesystem::path> plots;
    std::size_t rows = 0;
    std::size_t points = 0;
};

// Reads DIR/study.json and DIR/results.jsonl (InputError naming the file when
// they are missing or malformed) and writes DIR/report.html atomically.
ReportSummary writeReport(const std::filesystem::path& dir);

// Standard base64 (RFC 4648, with padding).
std::string base64(const std::string& bytes);
// Text with &, <, >, " escaped for HTML.
std::string htmlEscape(const std::string& text);

}  // namespace rtlab::study
