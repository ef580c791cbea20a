// rtlab report DIR: the HTML report of a sweep's results (docs/studies.md);
// the work is in the study library.
#include "commands.hpp"

#include <rtlab/study/report.hpp>

#include <iostream>

namespace rtlab::app {

void addReportCommand(CLI::App& app, ReportOptions& o) {
    CLI::App* cmd = app.add_subcommand("report", "Write DIR/report.html for a sweep's results (docs/studies.md)");
    cmd->add_option("dir", o.dir, "The sweep's --out directory")->required();
}

int runReport(const ReportOptions& o) {
    const study::ReportSummary s = study::writeReport(o.dir);
    if (!s.pdfProblem.empty()) std::cerr << "rtlab: warning: report: PDF figures not written: " << s.pdfProblem << "\n";
    std::cerr << "rtlab: report: " << s.rows << " of " << s.points << " point(s), " << s.plots.size()
              << " plot(s) as SVG, " << s.pdfs.size() << " as PDF, summary in " << s.summaryJson.string() << ": "
              << s.html.string() << "\n";
    return 0;
}

}  // namespace rtlab::app
