// Fuzz target: a scene description (.json, docs/scene-format.md: glTF models, builtin scenes, volumes, lights, camera paths).
// The input is written as case.json beside a fixed model.gltf (one triangle,
// its buffer a data URI; the seed gltf_model.json names it) and loaded and
// rendered as `rtlab render --scene case.json` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

#include <cstring>

namespace {
// scripts/mutate_inputs.py writes the same model beside its scene_json cases.
constexpr const char* kModel =
    R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],)"
    R"( "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],)"
    R"( "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",)"
    R"( "min": [0, 0, 0], "max": [1, 1, 0]}], "bufferViews": [{"buffer": 0, "byteLength": 36}],)"
    R"( "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,)"
    R"(AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]})";
}  // namespace

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    rtlab::fuzz::writeInput(reinterpret_cast<const std::uint8_t*>(kModel), std::strlen(kModel), "model.gltf");
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.json");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(path.string()); });
    return 0;
}
