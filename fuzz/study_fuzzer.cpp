// Fuzz target: a study file (.json, docs/studies.md), read as `rtlab sweep
// case.json` reads it before anything runs: parsed, every point expanded and
// its configuration resolved, each point's command line written.
#include "fuzz_input.hpp"

#include <rtlab/study/study.hpp>

RTLAB_FUZZ_INITIALIZE

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.json");
    rtlab::fuzz::expectingInputErrors([&] {
        const rtlab::study::Study study = rtlab::study::loadStudy(path);
        for (const rtlab::study::Point& p : rtlab::study::expandPoints(study))
            rtlab::study::renderArguments(study, p, "out", 1);
    });
    return 0;
}
