#pragma once
// The resumable result store of a sweep (docs/studies.md):
//
//   DIR/study.json               the study's canonical form and fingerprint
//   DIR/points/pNNNN/stats.json  the point's render statistics
//   DIR/points/pNNNN/result.json the point's row, written last: its presence
//                                means the point is complete
//   DIR/results.jsonl, .csv      every complete row, in point order (rebuilt
//                                from the result.json files when a sweep starts)
//
// Every file is written to a temporary name and renamed, so a kill at any
// moment leaves each point either complete or absent. A DIR holding another
// study's results is refused; one sweep at a time may hold a DIR (a lock).
#include <rtlab/core/timer.hpp>
#include <rtlab/study/study.hpp>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace rtlab::study {

class ResultStore {
public:
    // Opens DIR for `study` (read from `studyFile`), creating it when absent.
    // InputError when DIR holds another study, is not a sweep directory, or
    // another sweep holds it.
    ResultStore(const std::filesystem::path& dir, const Study& study, const std::string& studyFile);
    ~ResultStore();
    ResultStore(const ResultStore&) = delete;
    ResultStore& operator=(const ResultStore&) = delete;

    const std::filesystem::path& dir() const { return dir_; }
    std::filesystem::path pointDir(const Point& point) const;
    // Scratch space for running points (emptied when the store opens).
    std::filesystem::path scratchDir() const { return dir_ / ".scratch"; }

    // True when the point's row was recorded (by this or an earlier run).
    bool isDone(const Point& point) const { return rows_.count(point.index) != 0; }
    std::size_t doneCount() const { return rows_.size(); }

    // Records a finished point: its stats.json text (as `rtlab render` wrote
    // it), then its row (the point is then complete). Rewrites results.jsonl
    // and results.csv when the last rewrite is a second old or more (a study
    // of thousands of points does not rewrite them thousands of times);
    // flush() and the destructor bring them up to date. Returns the row.
    nlohmann::json record(const Point& point, const std::string& statsText, double wallSeconds);
    // Rewrites results.jsonl and results.csv if a recorded row is not in them yet.
    void flush();

    // The recorded rows, in point order.
    std::vector<nlohmann::json> rows() const;

private:
    void writeTables() const;

    std::filesystem::path dir_;
    Study study_;
    int lockFd_ = -1;
    std::map<std::size_t, nlohmann::json> rows_;
    bool tablesStale_ = false;
    Stopwatch sinceTables_;
};

// One result row (docs/studies.md): id, index, workload, overrides, metrics, timing.
nlohmann::json makeRow(const Point& point, const nlohmann::json& stats, double wallSeconds);
// The CSV text of `rows` (header + one line per row); `parameters` are the
// swept parameters, one column each.
std::string rowsToCsv(const std::vector<nlohmann::json>& rows, const std::vector<std::string>& parameters);
// DIR/results.jsonl's rows (InputError naming the file when missing or malformed).
std::vector<nlohmann::json> readRows(const std::filesystem::path& dir);
// DIR/study.json (InputError naming the file when missing or malformed).
nlohmann::json readStudyRecord(const std::filesystem::path& dir);

}  // namespace rtlab::study
