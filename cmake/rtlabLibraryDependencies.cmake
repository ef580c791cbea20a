# The third-party packages the rtlab libraries link, publicly or privately
# (static libraries carry their private dependencies to the final link, so a
# program using the installed package needs them all). Shared by the build
# (cmake/Dependencies.cmake: find_package ... REQUIRED) and the installed
# rtlabConfig.cmake (find_dependency), each defining rtlab_find_dependency().
rtlab_find_dependency(Threads)
rtlab_find_dependency(TBB)
rtlab_find_dependency(embree 3)
rtlab_find_dependency(glm)
rtlab_find_dependency(nlohmann_json 3)
rtlab_find_dependency(OpenEXR)
rtlab_find_dependency(TinyGLTF)
rtlab_find_dependency(draco CONFIG)          # KHR_draco_mesh_compression (libdraco-dev)
rtlab_find_dependency(meshoptimizer CONFIG)  # EXT_meshopt_compression (libmeshoptimizer-dev)
rtlab_find_dependency(tinyobjloader CONFIG)  # OBJ + MTL (libtinyobjloader-dev)
rtlab_find_dependency(assimp CONFIG)         # PLY and FBX (libassimp-dev)
# Debian's OpenVDB ships a find module, not a config file.
set(_rtlab_saved_module_path "${CMAKE_MODULE_PATH}")
list(APPEND CMAKE_MODULE_PATH /usr/lib/x86_64-linux-gnu/cmake/OpenVDB)
rtlab_find_dependency(OpenVDB)
set(CMAKE_MODULE_PATH "${_rtlab_saved_module_path}")
unset(_rtlab_saved_module_path)
