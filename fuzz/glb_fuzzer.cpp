// Fuzz target: binary glTF (.glb; Draco, meshopt and quantized geometry), read by tinygltf and ecs/src/load/gltf_*.cpp.
// The input is written as case.glb and loaded and rendered as
// `rtlab render --scene case.glb` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.glb");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(path.string()); });
    return 0;
}
