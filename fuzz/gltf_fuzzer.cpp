// Fuzz target: glTF 2.0 as JSON (.gltf; buffers and images as data: URIs), read by tinygltf and ecs/src/load/gltf_*.cpp.
// The input is written as case.gltf and loaded and rendered as
// `rtlab render --scene case.gltf` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

RTLAB_SCENE_FILE_FUZZER("gltf")
