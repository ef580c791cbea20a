#pragma once
// Internal: the bookkeeping of a sweep on the process that writes the store
// (the only process, or MPI rank 0): which points remain, what finished, the
// events, the exit code.
#include "point_process.hpp"

#include <rtlab/core/timer.hpp>
#include <rtlab/study/result_store.hpp>
#include <rtlab/study/sweep.hpp>

#include <deque>
#include <memory>
#include <vector>

namespace rtlab::study::detail {

class Coordinator {
public:
    Coordinator(const SweepOptions& options, const Study& study);

    const Study& study() const { return study_; }
    const std::vector<Point>& points() const { return points_; }
    ResultStore& store() { return *store_; }

    // Announces the run (Started event) with `workers` points at once.
    void start(int workers);
    // The next point to run; false when none remain or the sweep stops.
    bool next(std::size_t& index);
    // A point's outcome: recorded when complete, otherwise counted as failed
    // (a bad-input failure stops handing out points).
    void finished(std::size_t index, const PointOutcome& outcome);
    // Brings the result tables up to date, then: 0, 1 (a point failed) or
    // throws InputError (a point reported bad input).
    int exitCode() const;

private:
    SweepEvent event(SweepEvent::Kind kind) const;

    const SweepOptions& options_;
    const Study& study_;
    std::vector<Point> points_;
    std::unique_ptr<ResultStore> store_;
    std::deque<std::size_t> queue_;
    Stopwatch clock_;
    std::size_t skipped_ = 0, finished_ = 0, failed_ = 0, toRun_ = 0;
    int workers_ = 1;
    bool stop_ = false;
    std::string badInput_;
};

// Threads per point: the study's render.threads, else the cores shared among
// `concurrent` points (0 = all cores when one point runs at a time).
int threadsPerPoint(const Study& study, int concurrent);

#ifdef RTLAB_STUDY_HAS_MPI
int runMpiSweep(const SweepOptions& options);
#endif

}  // namespace rtlab::study::detail
