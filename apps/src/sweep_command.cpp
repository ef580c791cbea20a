// rtlab sweep STUDY.json --out DIR [--jobs N]
// (docs/studies.md); the work is in the study library.
#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/study/sweep.hpp>

#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <unistd.h>

namespace rtlab::app {

void addSweepCommand(CLI::App& app, SweepOptions& o) {
    CLI::App* cmd =
        app.add_subcommand("sweep",
                           "Run a study: every point (workload x RT-core overrides) once, resumable; under mpirun, "
                           "distributed (docs/studies.md)");
    cmd->add_option("study", o.study, "STUDY.json")->required();
    cmd->add_option("--out", o.out, "Result directory (rerun with the same DIR to resume)")->required();
    cmd->add_option("--jobs", o.jobs, "Points rendered at once on this machine")
        ->check(CLI::Range(1, 1024))
        ->capture_default_str();
}

namespace {

// Ctrl-C / SIGTERM: say how to resume, then die of the signal as before
// (the renders die with the sweep; complete points are kept).
void onInterrupt(int sig) {
    static const char message[] =
        "\nrtlab: sweep interrupted: complete points are kept; rerun the same command "
        "to resume\n";
    const ssize_t ignored = write(STDERR_FILENO, message, sizeof message - 1);
    (void)ignored;
    raise(sig);  // the handler was reset (SA_RESETHAND): the default action now
}

void sayHowToResumeOnInterrupt() {
    struct sigaction action;
    std::memset(&action, 0, sizeof action);
    action.sa_handler = onInterrupt;
    action.sa_flags = SA_RESETHAND;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
}

std::string seconds(double s) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.2f s", s);
    return buf;
}

}  // namespace

int runSweep(const SweepOptions& o) {
    study::SweepOptions options;
    options.studyFile = o.study;
    options.outDir = o.out;
    options.jobs = o.jobs;
    std::error_code ec;
    options.executable = std::filesystem::read_symlink("/proc/self/exe", ec).string();
    if (ec) throw std::runtime_error("cannot locate the rtlab executable (/proc/self/exe): " + ec.message());
    options.onEvent = [&](const study::SweepEvent& e) {
        using Kind = study::SweepEvent::Kind;
        if (e.kind == Kind::Started) {
            std::cerr << "rtlab: sweep " << o.study << ": " << e.total << " point(s), " << e.skipped
                      << " already complete in " << o.out << ", " << e.toRun << " to run, " << e.workers
                      << " at a time\n";
            progress(ProgressStep{"sweep: points", 0, e.toRun, 0.0, "running"});  // terminal only
            return;
        }
        const std::size_t ran = e.done - e.skipped + e.failed;
        if (e.kind == Kind::PointFailed) {
            progress("");
            std::cerr << "rtlab: sweep: " << e.message << "\n";
        }
        std::string detail = e.point->id + " " + (e.kind == Kind::PointDone ? "done" : "FAILED");
        if (e.row) detail += " in " + seconds(e.row->at("timing").value("wallSeconds", 0.0));
        progress(ProgressStep{"sweep: points", ran, e.toRun, e.elapsedSeconds, detail}, true);
    };
    if (study::launcherRank() == 0) sayHowToResumeOnInterrupt();
    const int code = study::runSweep(options);
    if (study::launcherRank() != 0) return code;  // MPI workers: rank 0 reports
    progress("");
    if (code == 0)
        std::cerr << "rtlab: sweep: results in " << (std::filesystem::path(o.out) / "results.csv").string()
                  << " (rtlab report " << o.out << " for plots)\n";
    else std::cerr << "rtlab: sweep: some points failed (see above); rerun the same command to retry them\n";
    return code;
}

}  // namespace rtlab::app
