#pragma once
// `rtlab sweep` (docs/studies.md): runs every unfinished point of a study and
// records it in the result store.
//
// Each point is one `rtlab render` child process (EXE render ... --out
// SCRATCH): a crash or kill of one point cannot corrupt another, N of them
// run side by side (--jobs N), and the child dies with the sweep (Linux
// parent-death signal), so a killed sweep leaves no orphans behind.
//
// Under mpirun (built with MPI: RTLAB_STUDY_HAS_MPI), rank 0 hands out points
// one at a time to ranks 1..R-1 as they become free (dynamic assignment: a
// slow point does not stall the others), receives each point's stats.json
// text and alone writes the store. Every rank runs its point as a child
// process as above, in a private temporary directory.
#include <rtlab/study/study.hpp>

#include <nlohmann/json.hpp>

#include <cstddef>
#include <filesystem>
#include <functional>
#include <string>

namespace rtlab::study {

struct SweepEvent {
    enum class Kind { Started, PointDone, PointFailed } kind = Kind::Started;
    std::size_t total = 0;                // points in the study
    std::size_t skipped = 0;              // complete before this run
    std::size_t done = 0;                 // complete now (skipped + finished in this run)
    std::size_t failed = 0;               // failed in this run
    std::size_t toRun = 0;                // points this run had to do
    double elapsedSeconds = 0.0;          // since this run started
    const Point* point = nullptr;         // PointDone / PointFailed
    const nlohmann::json* row = nullptr;  // PointDone
    std::string message;                  // PointFailed: why (the render's last stderr line)
    int workers = 1;                      // points run at once (jobs, or MPI ranks - 1)
};

struct SweepOptions {
    std::filesystem::path studyFile;
    std::filesystem::path outDir;
    int jobs = 1;            // points at once on this machine (ignored by MPI workers: one each)
    std::string executable;  // the rtlab binary to run as `EXE render ...`
    std::function<void(const SweepEvent&)> onEvent;  // on rank 0 only
};

// Runs the sweep; returns the exit code (0 every point complete; 1 some point
// failed internally; 2 bad input: an InputError is thrown for the study or
// DIR, and a point whose render reports bad input stops the sweep with 2).
int runSweep(const SweepOptions& options);

// True when started by an MPI launcher with more than one process
// (OMPI_COMM_WORLD_SIZE, PMI_SIZE or PMIX_SIZE > 1).
bool launchedByMpi();
// This process's rank as the MPI launcher set it (OMPI_COMM_WORLD_RANK,
// PMI_RANK); 0 when not launched by MPI.
int launcherRank();
// True when this build can distribute a sweep with MPI.
bool builtWithMpi();

}  // namespace rtlab::study
