// rtlab command line. Exit codes (DESIGN.md): 0 success, 2 bad input or
// usage (one line on stderr naming the file and the problem), 1 internal error.
#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/core/memory.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <unistd.h>

namespace rtlab::app {

namespace {
bool stderrIsTerminal() {
    static const bool terminal = isatty(STDERR_FILENO) != 0;
    return terminal;
}
}  // namespace

void progress(const std::string& line) {
    if (stderrIsTerminal()) std::cerr << "\r\033[K" << line << std::flush;
}

std::string etaText(double elapsedSeconds, std::size_t done, std::size_t total) {
    if (done == 0 || total < done) return "?";
    const long seconds = std::lround(elapsedSeconds / double(done) * double(total - done));
    char buf[32];
    if (seconds >= 3600)
        std::snprintf(buf, sizeof buf, "%ld:%02ld:%02ld", seconds / 3600, seconds / 60 % 60, seconds % 60);
    else
        std::snprintf(buf, sizeof buf, "%ld:%02ld", seconds / 60, seconds % 60);
    return buf;
}

void progress(const ProgressStep& step, bool logLine) {
    std::string line = step.what + " " + std::to_string(step.done) + "/" + std::to_string(step.total);
    if (!step.detail.empty()) line += ", " + step.detail;
    if (stderrIsTerminal())
        progress(line + ", ETA " + etaText(step.elapsedSeconds, step.done, step.total));
    else if (logLine)
        std::cerr << "rtlab: " << line << "\n";
}

void loadSceneWithWarnings(ecs::World& world, const std::string& source) {
    ecs::load::loadScene(world, source);
    for (const std::string& w : world.loadReport().warnings) std::cerr << "rtlab: warning: " << w << "\n";
}

}  // namespace rtlab::app

int main(int argc, char** argv) {
    using namespace rtlab;
    retainFreedMemory();
    CLI::App app{"rtlab: a deterministic ray-tracing laboratory"};
    app.require_subcommand(1);
    app::RenderOptions render;
    app::PlanOptions plan;
    app::InfoOptions info;
    app::CompareOptions compare;
    app::ConvergeOptions converge;
    app::ReplayOptions replay;
    app::SweepOptions sweep;
    app::ReportOptions reportOptions;
    app::addRenderCommand(app, render);
    app::addPlanCommand(app, plan);
    app::addInfoCommand(app, info);
    app::addCompareCommand(app, compare);
    app::addConvergeCommand(app, converge);
    app::addReplayCommand(app, replay);
    app::addSweepCommand(app, sweep);
    app::addReportCommand(app, reportOptions);

    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        std::cerr << "rtlab: " << e.what() << " (see rtlab --help)\n";
        return static_cast<int>(ExitCode::BadInput);
    }

    try {
        if (app.got_subcommand("render")) return app::runRender(render);
        if (app.got_subcommand("plan")) return app::runPlan(plan);
        if (app.got_subcommand("info")) return app::runInfo(info);
        if (app.got_subcommand("compare")) return app::runCompare(compare);
        if (app.got_subcommand("converge")) return app::runConverge(converge);
        if (app.got_subcommand("replay")) return app::runReplay(replay);
        if (app.got_subcommand("sweep")) return app::runSweep(sweep);
        if (app.got_subcommand("report")) return app::runReport(reportOptions);
    } catch (const InputError& e) {
        std::cerr << "rtlab: " << e.what() << "\n";
        return static_cast<int>(ExitCode::BadInput);
    } catch (const std::exception& e) {
        std::cerr << "rtlab: internal error: " << e.what() << "\n";
        return static_cast<int>(ExitCode::Internal);
    }
    return static_cast<int>(ExitCode::Internal);
}
