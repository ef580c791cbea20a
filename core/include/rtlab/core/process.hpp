#pragma once
// Starting a helper program (a fresh process, not a fork of this
// multi-threaded one): the report's rsvg-convert, the loader's assimp check.
#include <string>
#include <sys/types.h>
#include <vector>

namespace rtlab {

// Starts args[0] (searched on PATH) with args, stdout to /dev/null, stderr to
// `stderrFd` (or /dev/null when -1). Returns its pid, or -1 when it cannot start.
pid_t spawnProcess(const std::vector<std::string>& args, int stderrFd = -1);
// Waits for it (retrying on EINTR) and returns its wait status; -1 on failure.
int waitForProcess(pid_t pid);

}  // namespace rtlab
