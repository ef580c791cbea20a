// Fuzz target: binary glTF (.glb; Draco, meshopt and quantized geometry), read by tinygltf and ecs/src/load/gltf_*.cpp.
// The input is written as case.glb and loaded and rendered as
// `rtlab render --scene case.glb` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

RTLAB_SCENE_FILE_FUZZER("glb")
