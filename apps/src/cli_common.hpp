#pragma once
// What the rtlab subcommands share: the frame options on the command line
// (registered from session::frameOptionFields(), so a new option reaches
// every command that takes it), progress on stderr, and JSON of hits.
#include <rtlab/session/frame_options.hpp>
#include <rtlab/tracer/pipeline.hpp>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <string>

namespace rtlab::app {

// Adds every frame option whose uses include `use` (session::OptionUse) to
// `command`, bound to `options` (whose current values are the defaults
// shown). `--scene` is required when `sceneRequired`.
void addFrameOptions(CLI::App& command, session::FrameOptions& options, unsigned use, bool sceneRequired = false);

// --ray-types: "all" or a comma-separated list of ray-type names
// (shaders::rayTypeName), as a bit mask over ray types; InputError otherwise.
std::uint32_t rayTypeMask(const std::string& list);

// A JSON document as text (2-space indent). Strings from the scene's files
// (warnings, names) may be invalid UTF-8: written as U+FFFD, never thrown on.
std::string jsonText(const nlohmann::json& j);
// An error message as the one line rtlab prints: the control characters a
// file's bytes may bring (a newline in an EXR channel name) as \n, \r, \t
// or \xNN.
std::string oneLine(const std::string& message);
// A committed hit for stats.json ({"hit": false}, or t, instance, geometry, primitive).
nlohmann::json hitJson(const tracer::CommittedHit& hit);

// Progress of long work on stderr. progress(line): a line rewritten in place,
// only when stderr is a terminal ("" clears it).
void progress(const std::string& line);
// One step of counted work (frames of a render, points of a sweep): on a
// terminal, "WHAT DONE/TOTAL[, DETAIL], ETA M:SS" rewritten in place (the ETA
// from the rate so far); otherwise, with logLine, one plain line per step
// "rtlab: WHAT DONE/TOTAL[, DETAIL]" (a log file or CI), else nothing.
struct ProgressStep {
    std::string what;
    std::size_t done = 0;
    std::size_t total = 0;
    double elapsedSeconds = 0.0;  // for done steps
    std::string detail;
};
void progress(const ProgressStep& step, bool logLine = false);
// "M:SS" (or "H:MM:SS") left for total - done steps at the rate so far; "?" before the first step.
std::string etaText(double elapsedSeconds, std::size_t done, std::size_t total);

}  // namespace rtlab::app
