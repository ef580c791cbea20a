#include "coordinator.hpp"

#include <rtlab/core/error.hpp>

#include <algorithm>
#include <cstdlib>
#include <map>
#include <thread>

namespace rtlab::study {

namespace detail {

Coordinator::Coordinator(const SweepOptions& options, const Study& study)
    : options_(options), study_(study), points_(expandPoints(study)) {
    store_ = std::make_unique<ResultStore>(options.outDir, study, options.studyFile.string());
    for (const Point& p : points_) {
        if (store_->isDone(p)) ++skipped_;
        else queue_.push_back(p.index);
    }
    toRun_ = queue_.size();
}

SweepEvent Coordinator::event(SweepEvent::Kind kind) const {
    SweepEvent e;
    e.kind = kind;
    e.total = points_.size();
    e.skipped = skipped_;
    e.done = skipped_ + finished_;
    e.failed = failed_;
    e.toRun = toRun_;
    e.elapsedSeconds = clock_.elapsedMs() / 1000.0;
    e.workers = workers_;
    return e;
}

void Coordinator::start(int workers) {
    workers_ = workers;
    clock_.restart();
    if (options_.onEvent) options_.onEvent(event(SweepEvent::Kind::Started));
}

bool Coordinator::next(std::size_t& index) {
    if (stop_ || queue_.empty()) return false;
    index = queue_.front();
    queue_.pop_front();
    return true;
}

void Coordinator::finished(std::size_t index, const PointOutcome& outcome) {
    const Point& point = points_.at(index);
    if (outcome.exitCode == 0) {
        const nlohmann::json row = store_->record(point, outcome.statsText, outcome.wallSeconds);
        ++finished_;
        SweepEvent e = event(SweepEvent::Kind::PointDone);
        e.point = &point;
        e.row = &row;
        if (options_.onEvent) options_.onEvent(e);
        return;
    }
    ++failed_;
    std::string message = outcome.message;
    if (message.rfind("rtlab: ", 0) == 0) message = message.substr(7);
    message = "point " + point.id + " (" + point.workload.label() + ") exited with " +
              std::to_string(outcome.exitCode) + (message.empty() ? "" : ": " + message);
    if (outcome.exitCode == static_cast<int>(ExitCode::BadInput) && badInput_.empty()) {
        badInput_ = message;
        stop_ = true;
    }
    SweepEvent e = event(SweepEvent::Kind::PointFailed);
    e.point = &point;
    e.message = message;
    if (options_.onEvent) options_.onEvent(e);
}

int Coordinator::exitCode() const {
    store_->flush();
    if (!badInput_.empty()) throw InputError(options_.studyFile.string(), badInput_);
    return failed_ > 0 ? static_cast<int>(ExitCode::Internal) : 0;
}

int threadsPerPoint(const Study& study, int concurrent) {
    if (study.render.threads > 0) return study.render.threads;
    if (concurrent <= 1) return 0;
    const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    return std::max(1, cores / concurrent);
}

}  // namespace detail

namespace {

int runLocal(const SweepOptions& options) {
    const Study study = loadStudy(options.studyFile);
    detail::Coordinator coordinator(options, study);
    const int jobs = std::max(1, options.jobs);
    const int threads = detail::threadsPerPoint(study, jobs);
    coordinator.start(jobs);
    std::map<pid_t, detail::RunningPoint> running;
    for (;;) {
        std::size_t index = 0;
        while (static_cast<int>(running.size()) < jobs && coordinator.next(index)) {
            const Point& p = coordinator.points()[index];
            const std::filesystem::path scratch = coordinator.store().scratchDir() / p.id;
            detail::RunningPoint r = detail::startPoint(
                options.executable, renderArguments(study, p, scratch.string(), threads), index, scratch);
            running.emplace(r.pid, std::move(r));
        }
        if (running.empty()) break;
        pid_t pid = -1;
        int exitCode = 0;
        if (!detail::waitAny(pid, exitCode)) throw std::runtime_error("sweep: lost track of its render processes");
        const auto it = running.find(pid);
        if (it == running.end()) continue;  // not ours
        const detail::RunningPoint r = std::move(it->second);
        running.erase(it);
        coordinator.finished(r.index, detail::collectPoint(r, exitCode));
    }
    return coordinator.exitCode();
}

long envSize(const char* name) {
    const char* v = std::getenv(name);
    return v ? std::strtol(v, nullptr, 10) : 0;
}

}  // namespace

bool launchedByMpi() {
    return envSize("OMPI_COMM_WORLD_SIZE") > 1 || envSize("PMI_SIZE") > 1 || envSize("PMIX_SIZE") > 1;
}

int launcherRank() {
    if (!launchedByMpi()) return 0;
    const long ompi = envSize("OMPI_COMM_WORLD_RANK");
    return static_cast<int>(ompi > 0 ? ompi : envSize("PMI_RANK"));
}

bool builtWithMpi() {
#ifdef RTLAB_STUDY_HAS_MPI
    return true;
#else
    return false;
#endif
}

int runSweep(const SweepOptions& options) {
    if (options.executable.empty()) throw std::invalid_argument("runSweep: no executable");
    if (launchedByMpi()) {
#ifdef RTLAB_STUDY_HAS_MPI
        return detail::runMpiSweep(options);
#else
        throw InputError("sweep",
                         "started by an MPI launcher with several processes, but this rtlab was "
                         "built without MPI (install libopenmpi-dev and rebuild); run it once, "
                         "with --jobs N");
#endif
    }
    return runLocal(options);
}

}  // namespace rtlab::study
