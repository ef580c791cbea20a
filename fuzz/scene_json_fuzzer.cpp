// Fuzz target: a scene description (.json, docs/scene-format.md: glTF models, builtin scenes, volumes, lights, camera paths).
// The input is written as case.json and loaded and rendered as
// `rtlab render --scene case.json` would (fuzz_input.hpp).
#include "fuzz_input.hpp"

RTLAB_SCENE_FILE_FUZZER("json")
