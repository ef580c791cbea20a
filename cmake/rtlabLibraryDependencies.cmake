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
# OpenVDB is not among them: only rtlab's OpenVDB module links it (a shared
# module the ecs library opens at run time; cmake/Dependencies.cmake finds it).
