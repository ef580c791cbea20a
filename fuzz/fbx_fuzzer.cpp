// Fuzz target: FBX (ascii and binary), read by assimp in the separate check process (__check-file) and in process.
// The input is written as case.fbx and loaded and rendered as
// `rtlab render --scene case.fbx` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

RTLAB_SCENE_FILE_FUZZER("fbx")
