// rtlab command line. Exit codes (DESIGN.md): 0 success, 2 bad input or
// usage (one line on stderr naming the file and the problem), 1 internal error.
#include "cli_common.hpp"
#include "commands.hpp"

#include <rtlab/ecs/load/scene_loader.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/memory.hpp>

#include <iostream>

int main(int argc, char** argv) {
    using namespace rtlab;
    // The separate process that reads a file with assimp or OpenVDB first (a
    // crash or a hang of theirs stays there): `rtlab __check-file KIND PARENT_PID FILE [ARGUMENT]`.
    if ((argc == 5 || argc == 6) && std::string(argv[1]) == "__check-file")
        return ecs::load::runReaderCheck(argv[2], argv[3], argv[4], argc == 6 ? argv[5] : "");
    ecs::load::setReaderCheckCommand({"/proc/self/exe", "__check-file"});
    retainFreedMemory();
    CLI::App app{"rtlab: a deterministic ray-tracing laboratory"};
    app.require_subcommand(1);
    session::FrameOptions render;
    app::PlanOptions plan;
    app::InfoOptions info;
    app::CompareOptions compare;
    app::ConvergeOptions converge;
    app::ReplayOptions replay;
    app::SweepOptions sweep;
    app::ReportOptions reportOptions;
    app::GpuCheckExportOptions gpucheckExport;
    app::ExportOptions exportOptions;
    app::addRenderCommand(app, render);
    app::addPlanCommand(app, plan);
    app::addInfoCommand(app, info);
    app::addCompareCommand(app, compare);
    app::addConvergeCommand(app, converge);
    app::addReplayCommand(app, replay);
    app::addSweepCommand(app, sweep);
    app::addReportCommand(app, reportOptions);
    app::addGpuCheckExportCommand(app, gpucheckExport);
    app::addExportCommand(app, exportOptions);

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
        if (app.got_subcommand("gpucheck-export")) return app::runGpuCheckExport(gpucheckExport);
        if (app.got_subcommand("export")) return app::runExport(exportOptions);
    } catch (const InputError& e) {
        std::cerr << "rtlab: " << app::oneLine(e.what()) << "\n";
        return static_cast<int>(ExitCode::BadInput);
    } catch (const std::exception& e) {
        std::cerr << "rtlab: internal error: " << app::oneLine(e.what()) << "\n";
        return static_cast<int>(ExitCode::Internal);
    }
    return static_cast<int>(ExitCode::Internal);
}
