// Fuzz target: PLY (ascii and binary), header checked by rtlab, then read by assimp in the separate check process and in process.
// The input is written as case.ply and loaded and rendered as
// `rtlab render --scene case.ply` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.ply");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(path.string()); });
    return 0;
}
