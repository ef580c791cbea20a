#include <rtlab/study/result_store.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/study/metrics.hpp>

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <sstream>
#include <sys/file.h>
#include <unistd.h>

namespace rtlab::study {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr const char* kFormat = "rtlab-sweep/1";

json readJsonFile(const fs::path& path) {
    std::ifstream in(path);
    if (!in) throw InputError(path.string(), "cannot open");
    try {
        return json::parse(in);
    } catch (const json::exception& e) {  // parse_error, and out_of_range for numbers like 1e999
        throw InputError(path.string(), std::string("not valid JSON: ") + e.what());
    }
}

std::string csvField(const json& v) {
    if (v.is_null()) return "";
    std::string s = v.is_string() ? v.get<std::string>() : v.dump();
    if (s.find_first_of(",\"\n") == std::string::npos) return s;
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
}

}  // namespace

json makeRow(const Point& point, const json& stats, double wallSeconds) {
    json row;
    row["id"] = point.id;
    row["index"] = point.index;
    row["workload"] = point.workload.label();
    row["overrides"] = json::object();
    for (const Override& o : point.overrides) row["overrides"][o.key] = o.value;
    row["metrics"] = extractMetrics(stats);
    row["timing"] = extractTimings(stats);
    row["timing"]["wallSeconds"] = wallSeconds;
    return row;
}

std::string rowsToCsv(const std::vector<json>& rows, const std::vector<std::string>& parameters) {
    std::ostringstream out;
    out << "id,workload";
    for (const std::string& p : parameters) out << "," << csvField(p);
    for (const MetricInfo& m : metricList()) out << "," << m.name;
    out << "\n";
    for (const json& row : rows) {
        out << csvField(row.value("id", "")) << "," << csvField(row.value("workload", ""));
        const json overrides = row.value("overrides", json::object());
        for (const std::string& p : parameters) out << "," << csvField(overrides.value(p, json(nullptr)));
        for (const MetricInfo& m : metricList()) {
            const json group = row.value(m.timing ? "timing" : "metrics", json::object());
            out << "," << csvField(group.value(m.name, json(nullptr)));
        }
        out << "\n";
    }
    return out.str();
}

std::vector<json> readRows(const fs::path& dir) {
    const fs::path path = dir / "results.jsonl";
    std::ifstream in(path);
    if (!in) throw InputError(path.string(), "cannot open (run rtlab sweep first)");
    std::vector<json> rows;
    std::string line;
    for (int n = 1; std::getline(in, line); ++n) {
        if (line.empty()) continue;
        json row = json::parse(line, nullptr, false);
        if (row.is_discarded() || !row.is_object())
            throw InputError(path.string(), "line " + std::to_string(n) + ": not a JSON object");
        rows.push_back(std::move(row));
    }
    return rows;
}

json readStudyRecord(const fs::path& dir) {
    const fs::path path = dir / "study.json";
    if (!fs::exists(path)) throw InputError(dir.string(), "not a sweep directory (no study.json; run rtlab sweep)");
    json record = readJsonFile(path);
    if (!record.is_object() || record.value("format", "") != kFormat || !record.contains("study"))
        throw InputError(path.string(), std::string("not a sweep record (expected format ") + kFormat + ")");
    return record;
}

ResultStore::ResultStore(const fs::path& dir, const Study& study, const std::string& studyFile)
    : dir_(dir), study_(study) {
    const std::string where = dir.string();
    std::error_code ec;
    // Step: the directory: new, empty, or this study's.
    if (fs::exists(dir) && !fs::is_directory(dir)) throw InputError(where, "exists and is not a directory");
    const bool existed = fs::exists(dir / "study.json");
    if (!existed && fs::exists(dir))
        for (const fs::directory_entry& e : fs::directory_iterator(dir)) {
            // What a sweep killed before writing study.json leaves: an empty points/ and the lock.
            const std::string name = e.path().filename().string();
            if (name == ".lock" || (name == "points" && fs::is_directory(e.path()) && fs::is_empty(e.path()))) continue;
            throw InputError(where, "exists, is not empty and holds no sweep (no study.json): choose another --out");
        }
    fs::create_directories(dir / "points", ec);
    if (ec) throw InputError(where, "cannot create directory: " + ec.message());

    // Step: one sweep at a time (the lock goes with the process, even on SIGKILL).
    const fs::path lockPath = dir / ".lock";
    lockFd_ = ::open(lockPath.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (lockFd_ < 0) throw InputError(lockPath.string(), std::string("cannot open: ") + std::strerror(errno));
    if (::flock(lockFd_, LOCK_EX | LOCK_NB) != 0) {
        ::close(lockFd_);
        lockFd_ = -1;
        throw InputError(where, "another rtlab sweep is writing this directory");
    }

    // Step: the study record: written once, compared on every later run.
    if (existed) {
        const json record = readStudyRecord(dir);
        if (record.value("fingerprint", "") != study.fingerprint())
            throw InputError(studyFile, "differs from the study whose results are in " + where + " (from " +
                                            record.value("studyFile", std::string("?")) + ", fingerprint " +
                                            record.value("fingerprint", std::string("?")) + "; now " +
                                            study.fingerprint() +
                                            "): refusing to mix them; use another --out or remove " + where);
        // The same text may resolve to another model (a preset file or the
        // default preset changed since): its rows would not be comparable.
        if (study.render.backend == "rtcore" && record.contains("baseConfig") &&
            record["baseConfig"] != resolveConfig(study, nullptr, studyFile).toJson())
            throw InputError(studyFile,
                             "resolves to another RT-core configuration than the study whose results are in " + where +
                                 " (a preset or the default preset changed since; see its study.json "
                                 "baseConfig): refusing to mix them; use another --out or remove " +
                                 where);
    } else {
        json record;
        record["format"] = kFormat;
        record["fingerprint"] = study.fingerprint();
        record["studyFile"] = studyFile;
        record["study"] = study.toJson();
        record["points"] = expandPoints(study).size();
        record["parameters"] = sweptParameters(study);
        if (study.render.backend == "rtcore") record["baseConfig"] = resolveConfig(study, nullptr, studyFile).toJson();
        writeTextFileAtomically(dir / "study.json", record.dump(2) + "\n");
    }

    // Step: what earlier runs finished; leftovers of interrupted points go.
    fs::remove_all(scratchDir(), ec);
    for (const Point& p : expandPoints(study)) {
        const fs::path resultPath = pointDir(p) / "result.json";
        if (!fs::exists(resultPath)) continue;
        json row = json::parse(std::ifstream(resultPath), nullptr, false);
        if (row.is_discarded() || row.value("id", "") != p.id || row.value("workload", "") != p.workload.label())
            continue;  // unreadable: the point runs again
        rows_[p.index] = std::move(row);
    }
    writeTables();
    sinceTables_.restart();
}

ResultStore::~ResultStore() {
    try {
        flush();
    } catch (const std::exception&) {
        // The rows are safe in their result.json files; the next sweep rebuilds the tables.
    }
    if (lockFd_ >= 0) ::close(lockFd_);
}

fs::path ResultStore::pointDir(const Point& point) const { return dir_ / "points" / point.id; }

json ResultStore::record(const Point& point, const std::string& statsText, double wallSeconds) {
    const json stats = json::parse(statsText, nullptr, false);
    if (stats.is_discarded()) throw std::runtime_error("point " + point.id + ": stats.json is not valid JSON");
    const fs::path pd = pointDir(point);
    fs::create_directories(pd);
    writeTextFileAtomically(pd / "stats.json", statsText);
    json row = makeRow(point, stats, wallSeconds);
    writeTextFileAtomically(pd / "result.json", row.dump(2) + "\n");  // last: the point is complete
    rows_[point.index] = row;
    tablesStale_ = true;
    if (sinceTables_.elapsedMs() >= 1000.0) flush();
    return row;
}

void ResultStore::flush() {
    if (!tablesStale_) return;
    writeTables();
    tablesStale_ = false;
    sinceTables_.restart();
}

std::vector<json> ResultStore::rows() const {
    std::vector<json> out;
    for (const auto& [index, row] : rows_) out.push_back(row);
    return out;
}

void ResultStore::writeTables() const {
    const std::vector<json> all = rows();
    std::string jsonl;
    for (const json& row : all) jsonl += row.dump() + "\n";
    writeTextFileAtomically(dir_ / "results.jsonl", jsonl);
    writeTextFileAtomically(dir_ / "results.csv", rowsToCsv(all, sweptParameters(study_)));
}

}  // namespace rtlab::study
