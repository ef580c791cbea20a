// rtlab gpucheck-export: the files of the hardware check (docs/validation.md)
// from a recording made on the model: the model's BVH memory image, the
// selected rays, the model's answer per ray and its prediction of the
// caches and DRAM for them, for gpucheck/ to replay on an NVIDIA GPU.
#include "commands.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/session/frame_session.hpp>
#include <rtlab/study/gpucheck_export.hpp>
#include <rtlab/study/replay.hpp>

#include <iostream>

namespace rtlab::app {

void addGpuCheckExportCommand(CLI::App& app, GpuCheckExportOptions& o) {
    CLI::App* cmd = app.add_subcommand("gpucheck-export",
                                       "Write the files of the GPU check for recorded rays (docs/validation.md)");
    addFrameOptions(*cmd, o.frame, session::kUseReplay, true);
    cmd->add_option("--rays", o.rays,
                    "One .rays file recorded on the model (rtlab render --backend rtcore --record-rays)")
        ->required();
    cmd->add_option("--ray-types", o.rayTypes,
                    "all, or the rays of these ray types only: primary,shadow,reflection,ao,gi,translucency,pathBounce")
        ->capture_default_str();
    cmd->add_option("--max-rays", o.maxRays, "Export at most this many of the selected rays (0: all)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    cmd->add_option("--label", o.label, "The workload's name in model.json (e.g. terrain-primary)");
}

int runGpuCheckExport(const GpuCheckExportOptions& options) {
    const session::FrameOptions& o = options.frame;
    // Step: options and the recording, checked before the scene is loaded.
    if (o.backend != "rtcore")
        throw InputError("--backend", "gpucheck-export runs the RT-core model (leave --backend out or say rtcore)");
    study::GpuCheckSelection selection;
    selection.rayTypeMask = rayTypeMask(options.rayTypes);
    selection.maxRays = options.maxRays;
    selection.label = options.label;
    selection.scene = o.scene;
    const study::RayTraceFile file = study::RayTraceFile::read(options.rays);
    const std::uint32_t frame = file.header().frame;

    // Step: the scene as it was at the recorded frame (the model's BVHs see the same history).
    session::FrameSession s(o);
    // Parameters its one launch without shaders never uses are refused too.
    s.rtcore()->config().checkExplicitKeys("--rtcore-set", rtcore_sim::ConfigUse::GpuCheckExport);
    s.load();
    rtcore_sim::RtCoreBackend* rtcore = s.rtcore();
    const ecs::SceneSnapshot* scene = nullptr;
    for (std::uint32_t f = 0; f <= frame; ++f) scene = &s.advance().scene;
    study::checkReplayable(file, study::sceneFingerprint(*scene), rtcore);
    progress("exporting " + std::to_string(file.header().rayCount) + " recorded rays");
    const study::GpuCheckExportResult r =
        study::exportGpuCheck(file, rtcore->model(), rtcore->config(), selection, o.out);
    progress("");
    std::cerr << "rtlab: exported " << r.rays << " rays (left out: " << r.invalidRays << " invalid, " << r.otherVerdicts
              << " with verdicts other than commit-all or first-hit, " << r.beyondMaxRays
              << " beyond --max-rays) over a " << r.imageBytes << "-byte memory image to " << o.out << "\n";
    return 0;
}

}  // namespace rtlab::app
