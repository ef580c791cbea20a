#pragma once
// `rtlab report DIR` (docs/studies.md): DIR/report.html, one page (no
// scripts): the summary first (per workload the best and worst configuration
// by the study's objective, each swept parameter's effect; also
// DIR/summary.json), the parameter space, one plot per swept parameter and
// plotted metric (metric against the parameter's value, one line per workload
// and setting of the other parameters) inlined as SVG with a <title> per
// point, every point's row, the resolved base configuration and the commands
// that reproduce the study. Each plot is also written as
// DIR/plots/<metric>-vs-<parameter>.{svg,pdf,png,csv} (the PDF through
// rsvg-convert, fonts embedded; the CSV the rows drawn).
#include <filesystem>
#include <string>
#include <vector>

namespace rtlab::study {

struct ReportSummary {
    std::filesystem::path html;
    std::vector<std::filesystem::path> plots;  // the PNGs
    std::vector<std::filesystem::path> svgs, pdfs;
    std::filesystem::path summaryJson;
    std::string pdfProblem;  // why no PDF was written (rsvg-convert missing or failing); empty when all were
    std::size_t rows = 0;
    std::size_t points = 0;
};

// Reads DIR/study.json and DIR/results.jsonl (InputError naming the file when
// they are missing or malformed) and writes DIR/report.html atomically.
ReportSummary writeReport(const std::filesystem::path& dir);

// Text with &, <, >, " escaped for HTML.
std::string htmlEscape(const std::string& text);

}  // namespace rtlab::study
