# ctest package.install_and_examples (label "slow"): proves the installed
# package works. Installs the build tree into a scratch prefix, checks what
# landed there, then configures, builds and runs (through its own ctest) every
# project under examples/ out of tree, with only that prefix on
# CMAKE_PREFIX_PATH. Run as
#   cmake -DRTLAB_BINARY_DIR=... -DRTLAB_SOURCE_DIR=... -DWORK_DIR=... -DGENERATOR=...
#         [-DEXAMPLE_FLAGS="compile and link flags"] -P this-file
foreach(var RTLAB_BINARY_DIR RTLAB_SOURCE_DIR WORK_DIR GENERATOR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "install_and_build_examples.cmake: -D${var}=... is required")
  endif()
endforeach()

file(REMOVE_RECURSE "${WORK_DIR}/prefix")
file(MAKE_DIRECTORY "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")

function(run_step what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${out}")
  endif()
  message(STATUS "${what}: ok")
  set(step_output "${out}" PARENT_SCOPE)
endfunction()

run_step("install into ${prefix}" ${CMAKE_COMMAND} --install "${RTLAB_BINARY_DIR}" --prefix "${prefix}")
foreach(pattern include/rtlab/tracer/pipeline.hpp include/rtlab/rtcore_sim/scheduler.hpp include/rtlab/ecs/world.hpp include/rtlab/study/study.hpp
                lib*/librtlab_core.a lib*/librtlab_ecs.a lib*/librtlab_tracer.a lib*/librtlab_rtcore_sim.a
                lib*/librtlab_shaders_cpp.a lib*/librtlab_denoise.a lib*/librtlab_study.a lib*/cmake/rtlab/rtlabConfig.cmake
                lib*/cmake/rtlab/rtlabConfigVersion.cmake lib*/cmake/rtlab/rtlabTargets.cmake bin/rtlab
                lib*/rtlab/librtlab_openvdb.so
                share/doc/rtlab/api.md)
  file(GLOB found "${prefix}/${pattern}")
  if(NOT found)
    message(FATAL_ERROR "the install has no ${pattern}")
  endif()
endforeach()
# The installed rtlab opens the installed OpenVDB module (beside it, not the
# build tree's) when a scene has a volume: the showcase's procedural fog.
run_step("installed rtlab with a volume" ${CMAKE_COMMAND} -E env LD_DEBUG=files
         "${prefix}/bin/rtlab" info --scene builtin:showcase)
string(REGEX REPLACE "([][+.*?()^$|\\])" "\\\\\\1" prefix_pattern "${prefix}")  # the prefix taken literally
if(NOT step_output MATCHES "file=${prefix_pattern}/lib[^ ]*/rtlab/librtlab_openvdb\\.so")
  message(FATAL_ERROR "the installed rtlab did not open the installed OpenVDB module:\n${step_output}")
endif()
# Internal headers stay out of the package.
file(GLOB_RECURSE private_headers "${prefix}/include/*detail.hpp" "${prefix}/include/*render_context.hpp")
if(private_headers)
  message(FATAL_ERROR "internal headers were installed: ${private_headers}")
endif()

set(extra_args "")
find_program(CCACHE_PROGRAM ccache)
if(CCACHE_PROGRAM)
  list(APPEND extra_args "-DCMAKE_CXX_COMPILER_LAUNCHER=${CCACHE_PROGRAM}")
endif()
if(EXAMPLE_FLAGS)  # e.g. the sanitizers of an instrumented rtlab build
  list(APPEND extra_args "-DCMAKE_CXX_FLAGS=${EXAMPLE_FLAGS}" "-DCMAKE_EXE_LINKER_FLAGS=${EXAMPLE_FLAGS}")
endif()

file(GLOB examples LIST_DIRECTORIES true "${RTLAB_SOURCE_DIR}/examples/*")
set(count 0)
foreach(example ${examples})
  if(NOT EXISTS "${example}/CMakeLists.txt")
    continue()
  endif()
  get_filename_component(name "${example}" NAME)
  set(build "${WORK_DIR}/build-${name}")
  file(REMOVE_RECURSE "${build}")
  run_step("${name}: configure" ${CMAKE_COMMAND} -S "${example}" -B "${build}" -G "${GENERATOR}"
           -DCMAKE_BUILD_TYPE=Release "-DCMAKE_PREFIX_PATH=${prefix}" -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF ${extra_args})
  # The package came from the scratch prefix, not from the build tree.
  file(STRINGS "${build}/CMakeCache.txt" rtlab_dir REGEX "^rtlab_DIR:")
  string(FIND "${rtlab_dir}" "${prefix}/" at)
  if(NOT at GREATER -1)
    message(FATAL_ERROR "${name}: rtlab was not found in ${prefix} (${rtlab_dir})")
  endif()
  run_step("${name}: build" ${CMAKE_COMMAND} --build "${build}" --parallel 2)
  run_step("${name}: run" ${CMAKE_CTEST_COMMAND} --test-dir "${build}" --output-on-failure)
  if(NOT step_output MATCHES "100% tests passed")
    message(FATAL_ERROR "${name}: its ctest ran no test or not all passed:\n${step_output}")
  endif()
  math(EXPR count "${count} + 1")
endforeach()
if(count LESS 3)
  message(FATAL_ERROR "expected at least 3 example projects under ${RTLAB_SOURCE_DIR}/examples, built ${count}")
endif()
message(STATUS "${count} example projects built and run against the installed package")
