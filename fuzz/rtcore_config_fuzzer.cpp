// Fuzz target: an RT-core configuration (.json, docs/rtcore-model.md), read as
// `rtlab render --backend rtcore --rtcore-config case.json` reads it: parsed,
// validated, then a model built from it and a few rays traced on the Cornell box.
#include "fuzz_input.hpp"

#include <rtlab/session/frame_session.hpp>

RTLAB_FUZZ_INITIALIZE

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.json");
    rtlab::fuzz::expectingInputErrors([&] {
        rtlab::session::FrameOptions options;
        options.scene = "builtin:cornell";
        options.backend = "rtcore";
        options.rtcoreConfig = path.string();
        options.width = 4;
        options.height = 4;
        options.threads = 1;
        options.denoise = "none";
        options.effects = "gbuffer";
        rtlab::session::FrameSession s(options);
        s.load();
        s.advance();
        s.render();
    });
    return 0;
}
