#pragma once
// Scratch directories for tests: the process id is in the name (test runs of
// two checkouts, or a CI clone's, must not share directories), and every
// directory handed out is removed when the process exits.
#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

namespace rtlab::test {

// <temp>/rtlab_<pid>_<name>, empty (removed first, not created).
inline std::filesystem::path freshTempDir(const std::string& name) {
    struct Created {
        std::vector<std::filesystem::path> dirs;
        ~Created() {
            std::error_code ec;
            for (const std::filesystem::path& d : dirs) std::filesystem::remove_all(d, ec);
        }
    };
    static Created created;
    const std::filesystem::path d =
        std::filesystem::temp_directory_path() / ("rtlab_" + std::to_string(::getpid()) + "_" + name);
    std::error_code ec;
    std::filesystem::remove_all(d, ec);
    created.dirs.push_back(d);
    return d;
}

}  // namespace rtlab::test
