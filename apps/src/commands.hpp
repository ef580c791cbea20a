#pragma once
// The rtlab subcommands: one file each (NAME_command.cpp), each with its
// options, its CLI registration and its run function, which returns the
// process exit code; bad input is thrown as rtlab::InputError and turned into
// exit 2 by main(). What they share is in cli_common.hpp; every command that
// renders goes through session::FrameSession.
#include "cli_common.hpp"

#include <rtlab/session/frame_options.hpp>

#include <string>

namespace rtlab::app {

// rtlab render: the frame options as they are.
void addRenderCommand(CLI::App& app, session::FrameOptions& options);
int runRender(const session::FrameOptions& options);

// The frame options of a command whose --scene has no default (replay, plan).
inline session::FrameOptions frameOptionsWithoutScene(std::string out = "out") {
    session::FrameOptions o;
    o.scene.clear();
    o.out = std::move(out);
    return o;
}

struct ReplayOptions {
    session::FrameOptions frame = frameOptionsWithoutScene("out/replay");
    std::string rays;              // a .rays file or a directory of frame_NNNN.rays
    std::string rayTypes = "all";  // --ray-types all|LIST (primary,shadow,...)
};
void addReplayCommand(CLI::App& app, ReplayOptions& options);
int runReplay(const ReplayOptions& options);

struct GpuCheckExportOptions {
    session::FrameOptions frame = [] {
        session::FrameOptions o = frameOptionsWithoutScene("out/gpucheck");
        o.backend = "rtcore";
        return o;
    }();
    std::string rays;              // one .rays file recorded on the model
    std::string rayTypes = "all";  // --ray-types all|LIST
    std::uint64_t maxRays = 0;     // 0: all selected rays
    std::string label;             // model.json "label"
};
void addGpuCheckExportCommand(CLI::App& app, GpuCheckExportOptions& options);
int runGpuCheckExport(const GpuCheckExportOptions& options);

struct PlanOptions {
    session::FrameOptions frame = frameOptionsWithoutScene();
    bool json = false;
};
void addPlanCommand(CLI::App& app, PlanOptions& options);
int runPlan(const PlanOptions& options);

struct InfoOptions {
    std::string scene;
};
void addInfoCommand(CLI::App& app, InfoOptions& options);
int runInfo(const InfoOptions& options);

struct ExportOptions {
    std::string scene;
    std::string out;  // FILE.obj or FILE.ply
};
void addExportCommand(CLI::App& app, ExportOptions& options);
int runExport(const ExportOptions& options);

struct CompareOptions {
    std::string a, b;
};
void addCompareCommand(CLI::App& app, CompareOptions& options);
int runCompare(const CompareOptions& options);

struct ConvergeOptions {
    // The render options that shape the measured effect (session::kUseConverge).
    session::FrameOptions frame = [] {
        session::FrameOptions o;
        o.width = 480;
        o.height = 270;
        return o;
    }();
    std::string effect;
    std::string out;  // "" = out/converge/<scene>-<effect>
    std::string cache = "out/converge-cache";
    int referenceSpp = 4096;
    int maxSpp = 256;
    int denoiseMaxSpp = 4;
    int frames = 16;  // temporal history: 1, 2, 4 ... this many 1-spp frames
};
void addConvergeCommand(CLI::App& app, ConvergeOptions& options);
int runConverge(const ConvergeOptions& options);

struct SweepOptions {
    std::string study;
    std::string out;
    int jobs = 1;
};
void addSweepCommand(CLI::App& app, SweepOptions& options);
int runSweep(const SweepOptions& options);

struct ReportOptions {
    std::string dir;
};
void addReportCommand(CLI::App& app, ReportOptions& options);
int runReport(const ReportOptions& options);

}  // namespace rtlab::app
