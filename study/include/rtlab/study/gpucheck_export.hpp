#pragma once
// `rtlab gpucheck-export`: what the hardware check (gpucheck/, docs/validation.md)
// needs to replay recorded rays on a real GPU, as files: the model's BVH
// memory image at the timing model's addresses, the selected rays, the
// model's answer per ray (hit and traversal work), and the timing model's
// prediction of its caches and DRAM for the same rays as one launch.
#include <rtlab/rtcore_sim/config.hpp>
#include <rtlab/rtcore_sim/model_scene.hpp>
#include <rtlab/study/ray_trace_file.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <string>

namespace rtlab::study {

struct GpuCheckSelection {
    std::uint32_t rayTypeMask = 0xffff;  // ray types (RayContributionToHitGroupIndex & 0xf) to export
    std::uint64_t maxRays = 0;           // 0: all selected rays; else the first maxRays of them
    std::string label;                   // a name for the workload in model.json (e.g. "terrain-primary")
    std::string scene;                   // the scene source, named in errors about the scene
};

struct GpuCheckExportResult {
    std::uint64_t rays = 0;           // exported
    std::uint64_t invalidRays = 0;    // selected records the model does not trace (non-finite, tMax < tMin)
    std::uint64_t otherVerdicts = 0;  // selected rays whose verdicts are neither commit-all nor first-hit
    std::uint64_t beyondMaxRays = 0;  // selected rays left out by maxRays
    std::uint64_t imageBytes = 0;     // the memory image
    nlohmann::json model;             // model.json
};

// Writes scene.bin, rays.bin, expected.bin and model.json (gpucheck/include/gpucheck/format.hpp)
// into `out` (created; each file written under a temporary name and renamed).
// The recording must carry verdicts (recorded on the RT-core model in launch
// mode) and `scene` must be the scene it was recorded on, at its frame, built
// with config.bvh; scenes with procedural geometry are refused (InputError).
// The prediction runs the timing model with `config` over the exported rays
// as one launch of one thread per ray, from a cold start.
GpuCheckExportResult exportGpuCheck(const RayTraceFile& file, const rtcore_sim::ModelScene& scene,
                                    const rtcore_sim::RtCoreConfig& config, const GpuCheckSelection& selection,
                                    const std::filesystem::path& out);

}  // namespace rtlab::study
