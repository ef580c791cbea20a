// What the rtlab subcommands share (cli_common.hpp).
#include "cli_common.hpp"

#include <rtlab/core/error.hpp>
#include <rtlab/shaders_cpp/frame_renderer.hpp>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <type_traits>
#include <unistd.h>

namespace rtlab::app {

// --ray-types: "all" or a comma-separated list of ray-type names, as a bit mask.
std::uint32_t rayTypeMask(const std::string& list) {
    if (list == "all") return 0xffffu;
    std::uint32_t mask = 0;
    std::stringstream in(list);
    std::string item;
    while (std::getline(in, item, ',')) {
        if (item.empty()) continue;
        std::uint32_t t = 0;
        while (t < shaders::kRayTypeCount && shaders::rayTypeName(t) != item) ++t;
        if (t == shaders::kRayTypeCount) {
            std::string known;
            for (std::uint32_t k = 0; k < shaders::kRayTypeCount; ++k)
                known += (k ? ", " : "") + std::string(shaders::rayTypeName(k));
            throw InputError("--ray-types", "unknown ray type '" + item + "' (known: all, " + known + ")");
        }
        mask |= 1u << t;
    }
    if (!mask) throw InputError("--ray-types", "empty list (use all or ray-type names)");
    return mask;
}

void addFrameOptions(CLI::App& cmd, session::FrameOptions& o, unsigned use, bool sceneRequired) {
    for (const session::FrameOptionField& f : session::frameOptionFields()) {
        if (!(f.uses & use)) continue;
        std::visit(
            [&](auto member) {
                using T = std::remove_cvref_t<decltype(o.*member)>;
                T& value = o.*member;
                if constexpr (std::is_same_v<T, bool>) {
                    cmd.add_flag(f.flag, value, f.help);
                } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
                    cmd.add_option(f.flag, value, f.help)->allow_extra_args(false);
                } else {
                    CLI::Option* option = cmd.add_option(f.flag, value, f.help);
                    if constexpr (std::is_same_v<T, int>) {
                        if (f.ranged) option->check(CLI::Range(int(f.min), int(f.max)));
                    }
                    if constexpr (std::is_same_v<T, float>) {
                        if (f.ranged) option->check(CLI::Range(float(f.min), float(f.max)));
                    }
                    if constexpr (std::is_same_v<T, std::string>) {
                        if (!f.choices.empty()) option->check(CLI::IsMember(f.choices));
                    }
                    if (f.flag == "--scene" && sceneRequired) {
                        option->required();
                        return;
                    }
                    if constexpr (std::is_same_v<T, std::string>) {
                        if (value.empty()) return;  // no default to show
                    }
                    option->capture_default_str();
                }
            },
            f.member);
    }
}

std::string jsonText(const nlohmann::json& j) {
    return j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
}

std::string oneLine(const std::string& message) {
    std::string out;
    out.reserve(message.size());
    for (const char c : message) {
        const auto byte = static_cast<unsigned char>(c);
        if (byte >= 0x20 && byte != 0x7f) out += c;
        else if (c == '\n') out += "\\n";
        else if (c == '\r') out += "\\r";
        else if (c == '\t') out += "\\t";
        else {
            static const char* hex = "0123456789abcdef";
            out += "\\x";
            out += hex[byte >> 4];
            out += hex[byte & 15];
        }
    }
    return out;
}

nlohmann::json hitJson(const tracer::CommittedHit& h) {
    if (!h.hit) return {{"hit", false}};
    return {{"hit", true},
            {"t", h.t},
            {"instance", h.instanceIndex},
            {"geometry", h.geometryIndex},
            {"primitive", h.primitiveIndex}};
}

namespace {
bool stderrIsTerminal() {
    static const bool terminal = isatty(STDERR_FILENO) != 0;
    return terminal;
}
}  // namespace

void progress(const std::string& line) {
    if (stderrIsTerminal()) std::cerr << "\r\033[K" << line << std::flush;
}

std::string etaText(double elapsedSeconds, std::size_t done, std::size_t total) {
    if (done == 0 || total < done) return "?";
    const long seconds = std::lround(elapsedSeconds / double(done) * double(total - done));
    char buf[32];
    if (seconds >= 3600)
        std::snprintf(buf, sizeof buf, "%ld:%02ld:%02ld", seconds / 3600, seconds / 60 % 60, seconds % 60);
    else std::snprintf(buf, sizeof buf, "%ld:%02ld", seconds / 60, seconds % 60);
    return buf;
}

void progress(const ProgressStep& step, bool logLine) {
    std::string line = step.what + " " + std::to_string(step.done) + "/" + std::to_string(step.total);
    if (!step.detail.empty()) line += ", " + step.detail;
    if (stderrIsTerminal()) progress(line + ", ETA " + etaText(step.elapsedSeconds, step.done, step.total));
    else if (logLine) std::cerr << "rtlab: " << line << "\n";
}

}  // namespace rtlab::app
