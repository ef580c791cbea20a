// Fuzz target: a Wavefront material library (.mtl), read by tinyobjloader and
// ecs/src/load/obj_loader.cpp. The input is written as case.mtl beside a fixed
// OBJ (two triangles, `mtllib case.mtl`, `usemtl` of a name the seeds define)
// that is loaded and rendered as `rtlab render --scene case.obj` would.
#include "fuzz_input.hpp"

#include <cstring>

namespace {
constexpr const char* kObj =
    "mtllib case.mtl\n"
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
    "usemtl material\n"
    "f 1/1 2/2 3/3\n"
    "usemtl other\n"
    "f 1/1 3/3 4/4\n";
std::filesystem::path objPath;
}  // namespace

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
    rtlab::fuzz::initialize(argc, argv);
    objPath = rtlab::fuzz::writeInput(reinterpret_cast<const std::uint8_t*>(kObj), std::strlen(kObj), "case.obj");
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    rtlab::fuzz::writeInput(data, size, "case.mtl");
    rtlab::fuzz::expectingInputErrors([&] { rtlab::fuzz::loadAndRenderScene(objPath.string()); });
    return 0;
}
