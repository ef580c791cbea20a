// Fuzz target: Wavefront OBJ, read by tinyobjloader and ecs/src/load/obj_loader.cpp (no .mtl beside it: fuzz_mtl has those).
// The input is written as case.obj and loaded and rendered as
// `rtlab render --scene case.obj` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.obj");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(path.string()); });
    return 0;
}
