#pragma once
// What the fuzz targets share. Each target writes its input to a file (rtlab
// reads files, and its limits are checked against a file's size), in a
// directory of its own process, and calls the entry point the command line
// calls, with the same limits. An InputError is the expected answer to bad
// input (rtlab exits 2 with its one line); any other exception escapes the
// target and libFuzzer reports it as a finding (rtlab would exit 1, "internal
// error").
#include <rtlab/core/error.hpp>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

namespace rtlab::fuzz {

// Call from LLVMFuzzerInitialize. Runs `FUZZER __check-file KIND PID FILE
// [ARGUMENT]` when called so (the loaders' separate reader check, as `rtlab
// __check-file`) and exits; otherwise sets the check command (this
// executable, or $RTLAB_FUZZ_READER_CHECK: a release rtlab), creates the
// working directory and quiets the load notice.
void initialize(int* argc, char*** argv);

// Writes data to <working directory>/name; returns its path.
std::filesystem::path writeInput(const std::uint8_t* data, std::size_t size, const std::string& name);

// Copies a file to <working directory>/name (a fixed file beside the inputs).
void copyIntoWorkDirectory(const std::filesystem::path& source, const std::string& name);

// `rtlab info --scene SOURCE`, then, when it loaded, the first frame as
// `rtlab render --width 8 --height 8 --denoise none --threads 1` makes it
// (snapshot, acceleration structures, plan, every planned pass).
void loadAndRenderScene(const std::string& source);

// Runs f; an InputError is an answer, anything else escapes.
template <class F>
void expectingInputErrors(F&& f) {
    try {
        f();
    } catch (const InputError&) {}
}

}  // namespace rtlab::fuzz

// libFuzzer's initializer, calling rtlab::fuzz::initialize (every target has it).
#define RTLAB_FUZZ_INITIALIZE                                      \
    extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) { \
        rtlab::fuzz::initialize(argc, argv);                       \
        return 0;                                                  \
    }

// A whole target whose input is a scene file case.EXT, loaded and rendered
// (loadAndRenderScene): one line per scene format.
#define RTLAB_SCENE_FILE_FUZZER(EXT)                                                                \
    RTLAB_FUZZ_INITIALIZE                                                                           \
    extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {             \
        const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case." EXT);        \
        rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(path.string()); }); \
        return 0;                                                                                   \
    }
