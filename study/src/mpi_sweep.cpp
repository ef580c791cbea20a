// The sweep across MPI ranks (built only when CMake found MPI). Rank 0 owns
// the store and hands out point indices one at a time; ranks 1..R-1 run each
// point as a child process and send back its outcome (stats.json text
// included, so no shared file system is needed for the results).
#ifdef RTLAB_STUDY_HAS_MPI

#include "coordinator.hpp"

#include <rtlab/core/error.hpp>

// The C API only: not the deprecated C++ bindings (and their warnings).
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>

#include <chrono>
#include <cstdlib>
#include <thread>
#include <unistd.h>

namespace rtlab::study::detail {

namespace {

enum Tag : int { kReady = 1, kResult = 2, kWork = 3, kStop = 4 };

// MPI_Init / MPI_Finalize around the sweep.
class MpiSession {
public:
    MpiSession() {
        // OpenMPI's defaults that a sweep does not want: the warning about
        // fork() (each point is a child process; it never touches MPI), and
        // single-copy transfers between ranks, which need ptrace rights that
        // containers often lack. The user's environment still wins.
        setenv("OMPI_MCA_mpi_warn_on_fork", "0", 0);
        setenv("OMPI_MCA_btl_vader_single_copy_mechanism", "none", 0);
        MPI_Init(nullptr, nullptr);
        MPI_Comm_rank(MPI_COMM_WORLD, &rank);
        MPI_Comm_size(MPI_COMM_WORLD, &size);
    }
    ~MpiSession() { MPI_Finalize(); }
    MpiSession(const MpiSession&) = delete;
    MpiSession& operator=(const MpiSession&) = delete;
    int rank = 0;
    int size = 1;
};

void sendText(const std::string& text, int dest, int tag) {
    MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, dest, tag, MPI_COMM_WORLD);
}

// Waits (politely: polling with short sleeps, not MPI's busy wait) for a
// message from `source` and receives it.
std::string receive(int source, int& from, int& tag) {
    MPI_Status status;
    int flag = 0;
    for (;;) {
        MPI_Iprobe(source, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &status);
        if (flag) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    int count = 0;
    MPI_Get_count(&status, MPI_CHAR, &count);
    std::string text(static_cast<std::size_t>(count), '\0');
    MPI_Recv(text.data(), count, MPI_CHAR, status.MPI_SOURCE, status.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    from = status.MPI_SOURCE;
    tag = status.MPI_TAG;
    return text;
}

int coordinate(const SweepOptions& options, const MpiSession& mpi) {
    int stopped = 0;  // workers told to stop (each then sends nothing more)
    try {
        const Study study = loadStudy(options.studyFile);
        Coordinator coordinator(options, study);
        coordinator.start(mpi.size - 1);
        while (stopped < mpi.size - 1) {
            int from = 0, tag = 0;
            const std::string text = receive(MPI_ANY_SOURCE, from, tag);
            if (tag == kResult) {
                const nlohmann::json message = nlohmann::json::parse(text);
                PointOutcome outcome;
                outcome.exitCode = message.at("exitCode").get<int>();
                outcome.wallSeconds = message.at("wallSeconds").get<double>();
                outcome.statsText = message.at("stats").get<std::string>();
                outcome.message = message.at("message").get<std::string>();
                coordinator.finished(message.at("index").get<std::size_t>(), outcome);
            }
            std::size_t index = 0;
            if (coordinator.next(index)) {
                sendText(std::to_string(index), from, kWork);
            } else {
                sendText("", from, kStop);
                ++stopped;
            }
        }
        return coordinator.exitCode();
    } catch (...) {
        // Release every worker still waiting or running (its next message
        // gets a stop), so that all ranks reach MPI_Finalize.
        while (stopped < mpi.size - 1) {
            int from = 0, tag = 0;
            receive(MPI_ANY_SOURCE, from, tag);
            sendText("", from, kStop);
            ++stopped;
        }
        throw;
    }
}

int work(const SweepOptions& options, const MpiSession& mpi) {
    Study study;
    try {
        study = loadStudy(options.studyFile);
    } catch (const InputError&) {
        study = Study{};  // rank 0 reports it and releases this rank
    }
    const std::vector<Point> points = expandPoints(study);
    const char* local = std::getenv("OMPI_COMM_WORLD_LOCAL_SIZE");
    const int localRanks = local ? std::max(1, std::atoi(local)) : mpi.size;
    const int threads = threadsPerPoint(study, localRanks);
    const std::filesystem::path scratchRoot =
        std::filesystem::temp_directory_path() / ("rtlab-sweep-" + std::to_string(getpid()));
    sendText("", 0, kReady);
    for (;;) {
        int from = 0, tag = 0;
        const std::string text = receive(0, from, tag);
        if (tag != kWork) break;
        const std::size_t index = std::stoul(text);
        PointOutcome outcome;
        if (index < points.size()) {
            const Point& p = points[index];
            const std::filesystem::path scratch = scratchRoot / p.id;
            const RunningPoint running =
                startPoint(options.executable, renderArguments(study, p, scratch.string(), threads), index, scratch);
            pid_t pid = -1;
            int exitCode = 1;
            while (waitAny(pid, exitCode) && pid != running.pid) {}
            outcome = collectPoint(running, exitCode);
        } else {
            outcome.message = "rank " + std::to_string(mpi.rank) + " has no point " + text +
                              " (does every rank read the same study file?)";
        }
        const nlohmann::json message = {{"index", index},
                                        {"exitCode", outcome.exitCode},
                                        {"wallSeconds", outcome.wallSeconds},
                                        {"stats", outcome.statsText},
                                        {"message", outcome.message}};
        sendText(message.dump(), 0, kResult);
    }
    std::error_code ec;
    std::filesystem::remove_all(scratchRoot, ec);
    return 0;
}

}  // namespace

int runMpiSweep(const SweepOptions& options) {
    MpiSession mpi;
    if (mpi.size < 2) return 0;  // unreachable: launchedByMpi() saw more than one process
    return mpi.rank == 0 ? coordinate(options, mpi) : work(options, mpi);
}

}  // namespace rtlab::study::detail

#endif  // RTLAB_STUDY_HAS_MPI
