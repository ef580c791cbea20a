// The named RT-core presets (rtcore_sim/presets/*.json), built in by
// rtcore_sim/CMakeLists.txt so that `--rtcore-config NAME` works from any
// directory; the same files are installed to share/rtlab/rtcore-presets.
#include <rtlab/rtcore_sim/config.hpp>

#include <string>
#include <utility>
#include <vector>

namespace rtlab::rtcore_sim {
namespace {

const std::vector<std::pair<std::string, const char*>>& presets() {
    static const std::vector<std::pair<std::string, const char*>> list = {
#include "rtcore_presets.inc"
    };
    return list;
}

}  // namespace

std::vector<std::string> rtcorePresetNames() {
    std::vector<std::string> names;
    for (const auto& [name, text] : presets()) names.push_back(name);
    return names;
}

const char* rtcorePresetText(const std::string& name) {
    for (const auto& [n, text] : presets())
        if (n == name) return text;
    return nullptr;
}

}  // namespace rtlab::rtcore_sim
