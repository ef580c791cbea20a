// Fuzz target: PLY (ascii and binary), header checked by rtlab, then read by assimp in the separate check process and in process.
// The input is written as case.ply and loaded and rendered as
// `rtlab render --scene case.ply` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

RTLAB_SCENE_FILE_FUZZER("ply")
