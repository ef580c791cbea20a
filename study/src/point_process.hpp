#pragma once
// Internal: one point as a child process `EXE render ... --out SCRATCH`, its
// stdout and stderr in SCRATCH/render.log.
#include <rtlab/core/timer.hpp>

#include <filesystem>
#include <string>
#include <sys/types.h>
#include <vector>

namespace rtlab::study::detail {

struct PointOutcome {
    int exitCode = 1;  // the render's exit code; 128 + signal when killed
    double wallSeconds = 0.0;
    std::string statsText;  // SCRATCH/stats.json when the render succeeded
    std::string message;    // the last non-empty line of the render's output
};

struct RunningPoint {
    pid_t pid = -1;
    std::size_t index = 0;
    std::filesystem::path scratch;
    Stopwatch clock;
};

// Starts `executable args...` (args already end with --out scratch), the
// child killed when this process dies. Throws std::runtime_error when it cannot.
RunningPoint startPoint(const std::string& executable, const std::vector<std::string>& args, std::size_t index,
                        const std::filesystem::path& scratch);
// Waits for any started child; returns false when there is none.
bool waitAny(pid_t& pid, int& exitCode);
// What a finished child left in its scratch directory (which is then removed).
PointOutcome collectPoint(const RunningPoint& running, int exitCode);

}  // namespace rtlab::study::detail
