// Fuzz target: glTF 2.0 as JSON (.gltf; buffers and images as data: URIs), read by tinygltf and ecs/src/load/gltf_*.cpp.
// The input is written as case.gltf and loaded and rendered as
// `rtlab render --scene case.gltf` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.gltf");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(path.string()); });
    return 0;
}
