#include "reader_check.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/core/process.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <new>
#include <stdexcept>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#if defined(__SANITIZE_ADDRESS__)  // GCC
#define RTLAB_UNDER_ASAN 1
#elif defined(__has_feature)  // clang
#if __has_feature(address_sanitizer)
#define RTLAB_UNDER_ASAN 1
#endif
#endif

namespace rtlab::ecs::load {
namespace {

std::vector<std::string>& checkCommand() {
    static std::vector<std::string> command;
    return command;
}

// The check process's address space: 1 GiB + 256 bytes per byte of the file
// (a compressed VDB or FBX array may expand that much; a corrupt header
// declaring more fails its allocation, an InputError, instead of exhausting
// the machine). Not under AddressSanitizer, which reserves terabytes.
void limitCheckMemory([[maybe_unused]] const std::filesystem::path& path) {
#if !defined(RTLAB_UNDER_ASAN)
    std::error_code ec;
    const std::uint64_t bytes = std::filesystem::file_size(path, ec);
    const rlim_t cap = rlim_t(1) * 1024 * 1024 * 1024 + 256 * rlim_t(ec ? 0 : bytes);
    const rlimit limit{cap, cap};
    setrlimit(RLIMIT_AS, &limit);
#endif
}

}  // namespace

double checkSecondsLimit(std::uint64_t fileBytes) {
    const double kilobytes = double(fileBytes) / 1024.0;
    return std::max(2.0, std::min(kilobytes, 30.0 + 2.0 * kilobytes / 1024.0));
}

void checkInSeparateProcess(const std::string& kind, const std::string& library, const std::filesystem::path& path,
                            const std::string& argument, const std::string& where) {
    if (checkCommand().empty()) return;  // no check command: read in process
    int fds[2];
    if (pipe2(fds, O_CLOEXEC) != 0) return;
    std::vector<std::string> args = checkCommand();
    args.push_back(kind);
    args.push_back(std::to_string(getpid()));
    args.push_back(path.string());
    if (!argument.empty()) args.push_back(argument);
    const pid_t pid = spawnProcess(args, fds[1]);
    close(fds[1]);
    if (pid < 0) {
        close(fds[0]);
        return;  // the check cannot start: read in process
    }
    std::error_code ec;
    const double limit = checkSecondsLimit(ec ? 0 : std::filesystem::file_size(path, ec));
    std::string message;
    const auto started = std::chrono::steady_clock::now();
    int status = 0;
    bool exited = false;
    for (;;) {
        pollfd p{fds[0], POLLIN, 0};
        if (poll(&p, 1, 20) > 0) {
            char buffer[4096];
            const ssize_t n = read(fds[0], buffer, sizeof buffer);
            if (n > 0 && message.size() < 65536) message.append(buffer, std::size_t(n));
        }
        const pid_t done = waitpid(pid, &status, WNOHANG);
        if (done == pid) {
            exited = true;
            break;
        }
        if (done < 0 && errno != EINTR) {  // not ours to wait for (SIGCHLD ignored): read in process
            close(fds[0]);
            return;
        }
        if (std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() > limit) {
            kill(pid, SIGKILL);
            status = waitForProcess(pid);
            break;
        }
    }
    for (char buffer[4096];;) {  // what is left in the pipe
        const ssize_t n = read(fds[0], buffer, sizeof buffer);
        if (n <= 0 || message.size() >= 65536) break;
        message.append(buffer, std::size_t(n));
    }
    close(fds[0]);
    if (!exited) {
        char text[64];
        std::snprintf(text, sizeof text, "%.0f", limit);
        throw InputError(where,
                         library + " did not finish reading it within " + text + " s (it hangs on some corrupt files)");
    }
    if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return;
    if (WIFEXITED(status) && WEXITSTATUS(status) == 2) {
        // The check's one line, "rtlab: FILE: problem": the problem after the file.
        std::string line = message.substr(0, message.find('\n'));
        const std::size_t at = line.find(where + ": ");
        if (at != std::string::npos) throw InputError(where, line.substr(at + where.size() + 2));
        throw InputError(where, line.empty() ? "unreadable" : line);
    }
    // The check's own fault, not the file's: exit 1 with its one line (a
    // sanitizer's report also exits 1, and that is a crash reading the file).
    const std::string internal = "rtlab: internal error: ";
    if (WIFEXITED(status) && WEXITSTATUS(status) == 1 && message.rfind(internal, 0) == 0)
        throw std::runtime_error("the separate-process check of " + where +
                                 " failed: " + message.substr(internal.size(), message.find('\n') - internal.size()));
    const std::string how =
        WIFSIGNALED(status) ? std::string(strsignal(WTERMSIG(status))) : "exit " + std::to_string(WEXITSTATUS(status));
    throw InputError(where, library + " crashed reading it (" + how +
                                "): the file is corrupt (rtlab reads such files in a separate process first)");
}

void setReaderCheckCommand(std::vector<std::string> command) { checkCommand() = std::move(command); }

int runReaderCheck(const std::string& kind, const std::string& parentPid, const std::filesystem::path& path,
                   const std::string& argument) {
    // Dies with the process that asked (a hang must not outlive it); glibc's
    // abort message goes to stderr (the asker's pipe), not the terminal.
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (std::to_string(getppid()) != parentPid) return 3;
    setenv("LIBC_FATAL_STDERR_", "1", 1);
    limitCheckMemory(path);
    try {
        if (kind == "assimp") readWithAssimpForCheck(path);
        else if (kind == "vdb") readVdbForCheck(path, argument);
        else return 3;
    } catch (const InputError& e) {
        std::fprintf(stderr, "rtlab: %s\n", e.what());
        return 2;
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "rtlab: %s: implausible sizes (more memory than the check allows)\n", path.c_str());
        return 2;
    } catch (const std::exception& e) {  // not the file's fault (e.g. the OpenVDB module is missing)
        std::fprintf(stderr, "rtlab: internal error: %s\n", e.what());
        return 1;
    }
    return 0;
}

}  // namespace rtlab::ecs::load
