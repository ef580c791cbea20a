// Fuzz target: Wavefront OBJ, read by tinyobjloader and ecs/src/load/obj_loader.cpp (no .mtl beside it: fuzz_mtl has those).
// The input is written as case.obj and loaded and rendered as
// `rtlab render --scene case.obj` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

RTLAB_SCENE_FILE_FUZZER("obj")
