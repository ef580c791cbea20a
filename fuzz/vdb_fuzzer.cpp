// Fuzz target: an OpenVDB file (.vdb), checked by ecs/src/load/vdb_volume.cpp
// and read by OpenVDB. The input is written as case.vdb, named by a fixed scene
// .json (a fog volume over a floor), which is loaded and rendered as `rtlab
// render --scene case.json` would.
#include "fuzz_input.hpp"

#include <cstring>

namespace {
constexpr const char* kScene =
    R"({"name": "fuzzed volume", "gltf": [], "volumes": [{"file": "case.vdb", "densityScale": 0.5}],)"
    R"( "camera": {"position": [0, 1, 6], "lookAt": [0, 0, 0], "yfov": 0.8}})";
std::filesystem::path scenePath;
}  // namespace

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    scenePath =
        rtlab::fuzz::writeInput(reinterpret_cast<const std::uint8_t*>(kScene), std::strlen(kScene), "case.json");
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    rtlab::fuzz::writeInput(data, size, "case.vdb");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(scenePath.string()); });
    return 0;
}
