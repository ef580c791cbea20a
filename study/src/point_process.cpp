#include "point_process.hpp"

#include <cerrno>
#include <csignal>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

namespace rtlab::study::detail {

namespace fs = std::filesystem;

namespace {

std::string readFile(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return {};
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string lastLine(const std::string& text) {
    std::size_t end = text.find_last_not_of("\r\n \t");
    if (end == std::string::npos) return {};
    const std::size_t begin = text.find_last_of('\n', end);
    std::string line =
        text.substr(begin == std::string::npos ? 0 : begin + 1, end + 1 - (begin == std::string::npos ? 0 : begin + 1));
    const std::size_t cr = line.find_last_of('\r');  // progress lines of a terminal
    return cr == std::string::npos ? line : line.substr(cr + 1);
}

}  // namespace

RunningPoint startPoint(const std::string& executable, const std::vector<std::string>& args, std::size_t index,
                        const fs::path& scratch) {
    fs::remove_all(scratch);
    fs::create_directories(scratch);
    const std::string logPath = (scratch / "render.log").string();
    // Everything the child needs is prepared before fork (no allocation after it).
    std::vector<std::string> argvStrings;
    argvStrings.push_back(executable);
    argvStrings.insert(argvStrings.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& s : argvStrings) argv.push_back(s.data());
    argv.push_back(nullptr);
    const pid_t parent = getpid();

    RunningPoint running;
    running.index = index;
    running.scratch = scratch;
    const pid_t pid = fork();
    if (pid < 0) throw std::runtime_error(std::string("fork failed: ") + std::strerror(errno));
    if (pid == 0) {
        // Child: die with the sweep (SIGKILL on the parent's death, even SIGKILL).
        prctl(PR_SET_PDEATHSIG, SIGKILL);
        if (getppid() != parent) _exit(127);
        const int log = open(logPath.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        const int null = open("/dev/null", O_RDONLY);
        if (log < 0 || null < 0) _exit(127);
        dup2(null, STDIN_FILENO);
        dup2(log, STDOUT_FILENO);
        dup2(log, STDERR_FILENO);
        execv(argv[0], argv.data());
        _exit(127);
    }
    running.pid = pid;
    return running;
}

bool waitAny(pid_t& pid, int& exitCode) {
    int status = 0;
    for (;;) {
        pid = waitpid(-1, &status, 0);
        if (pid >= 0) break;
        if (errno == EINTR) continue;
        return false;  // ECHILD: none left
    }
    exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    return true;
}

PointOutcome collectPoint(const RunningPoint& running, int exitCode) {
    PointOutcome o;
    o.exitCode = exitCode;
    o.wallSeconds = running.clock.elapsedMs() / 1000.0;
    if (exitCode == 0) o.statsText = readFile(running.scratch / "stats.json");
    const std::string log = readFile(running.scratch / "render.log");
    o.message = lastLine(log);
    if (exitCode == 127 && o.message.empty()) o.message = "could not start the render process";
    if (exitCode > 128 && o.message.empty()) o.message = "killed by signal " + std::to_string(exitCode - 128);
    if (exitCode == 0 && o.statsText.empty()) {
        o.exitCode = 1;
        o.message = "the render wrote no stats.json";
    }
    std::error_code ec;
    if (o.exitCode == 0) fs::remove_all(running.scratch, ec);  // a failed point's log stays until the next sweep
    return o;
}

}  // namespace rtlab::study::detail
