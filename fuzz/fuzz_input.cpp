#include "fuzz_input.hpp"

#include <rtlab/ecs/load/scene_loader.hpp>
#include <rtlab/session/frame_session.hpp>

#include <cstdio>
#include <cstdlib>
#include <string_view>
#include <unistd.h>

namespace rtlab::fuzz {
namespace {

std::filesystem::path& workDirectory() {
    static std::filesystem::path dir;
    return dir;
}

}  // namespace

void initialize(int* argc, char*** argv) {
    if ((*argc == 5 || *argc == 6) && std::string_view((*argv)[1]) == "__check-file")
        std::exit(ecs::load::runReaderCheck((*argv)[2], (*argv)[3], (*argv)[4], *argc == 6 ? (*argv)[5] : ""));
    // The check may be a release rtlab (scripts/fuzz.py sets it): it starts in
    // a tenth of the time this instrumented executable takes.
    const char* check = std::getenv("RTLAB_FUZZ_READER_CHECK");
    ecs::load::setReaderCheckCommand({check && *check ? check : "/proc/self/exe", "__check-file"});
    setenv("RTLAB_LOAD_NOTICE_SECONDS", "1e9", 1);
    const char* tmp = std::getenv("TMPDIR");
    std::filesystem::path dir =
        std::filesystem::path(tmp && *tmp ? tmp : "/tmp") / ("rtlab_fuzz_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir);
    workDirectory() = dir;
    std::atexit([] {
        std::error_code ec;
        std::filesystem::remove_all(workDirectory(), ec);
    });
}

std::filesystem::path writeInput(const std::uint8_t* data, std::size_t size, const std::string& name) {
    const std::filesystem::path path = workDirectory() / name;
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) std::abort();
    if (size && std::fwrite(data, 1, size, f) != size) std::abort();
    std::fclose(f);
    return path;
}

void copyIntoWorkDirectory(const std::filesystem::path& source, const std::string& name) {
    std::filesystem::copy_file(source, workDirectory() / name, std::filesystem::copy_options::overwrite_existing);
}

void loadAndRenderScene(const std::string& source) {
    session::FrameOptions options;
    options.scene = source;
    options.width = 8;
    options.height = 8;
    options.threads = 1;
    options.denoise = "none";
    session::FrameSession s(options);
    s.load();
    s.advance();
    s.render();
}

}  // namespace rtlab::fuzz
