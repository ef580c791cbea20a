// Fuzz target: FBX (ascii and binary), read by assimp in the separate check process (__check-file) and in process.
// The input is written as case.fbx and loaded and rendered as
// `rtlab render --scene case.fbx` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.fbx");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(path.string()); });
    return 0;
}
