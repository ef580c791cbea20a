// Fuzz target: a scene description (.json, docs/scene-format.md: glTF models, builtin scenes, volumes, lights, camera paths).
// The input is written as case.json beside fuzz/scene_json_model.gltf, copied
// as model.gltf (one triangle, its buffer a data URI; the seed gltf_model.json
// names it), and loaded and rendered as `rtlab render --scene case.json` would
// (fuzz_input.hpp). scripts/mutate_inputs.py and the regression test put the
// same model beside their scene_json cases.
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    rtlab::fuzz::copyIntoWorkDirectory(RTLAB_FUZZ_SCENE_JSON_MODEL, "model.gltf");
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::filesystem::path path = rtlab::fuzz::writeInput(data, size, "case.json");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(path.string()); });
    return 0;
}
