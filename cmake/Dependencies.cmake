# Every third-party dependency, found once. All come from Debian packages
# installed by scripts/install-deps.sh. The libraries' own dependencies are
# listed in rtlabLibraryDependencies.cmake, which the installed package's
# rtlabConfig.cmake reuses.
macro(rtlab_find_dependency)
  find_package(${ARGV} REQUIRED)
endmacro()
include(${CMAKE_CURRENT_LIST_DIR}/rtlabLibraryDependencies.cmake)
find_package(CLI11 REQUIRED)
# OpenVDB, for rtlab's OpenVDB module (ecs/CMakeLists.txt) only. Debian's
# OpenVDB ships a find module, not a config file.
list(APPEND CMAKE_MODULE_PATH /usr/lib/x86_64-linux-gnu/cmake/OpenVDB)
find_package(OpenVDB REQUIRED)
list(POP_BACK CMAKE_MODULE_PATH)
# OpenMPI (libopenmpi-dev) for distributed sweeps: optional. RTLAB_WITH_MPI
# is ON when found; -DRTLAB_USE_MPI=OFF builds without it even then.
option(RTLAB_USE_MPI "Distribute rtlab sweep with MPI when MPI is found" ON)
set(RTLAB_WITH_MPI OFF)
if(RTLAB_USE_MPI)
  find_package(MPI COMPONENTS CXX)
  if(MPI_CXX_FOUND)
    set(RTLAB_WITH_MPI ON)
  endif()
endif()
message(STATUS "rtlab: distributed sweeps with MPI: ${RTLAB_WITH_MPI}")
if(RTLAB_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
if(RTLAB_BUILD_BENCH)
  find_package(benchmark REQUIRED)
endif()
if(NOT EXISTS /usr/include/stb/stb_image_write.h)
  message(FATAL_ERROR "stb headers missing: run scripts/install-deps.sh (libstb-dev)")
endif()

# rtlab_add_module(NAME DEPS ...): one library per top-level folder, sources
# globbed from NAME/src, public headers in NAME/include/rtlab/NAME. Each is
# installed and exported as rtlab::NAME (the package: top-level CMakeLists.txt).
function(rtlab_add_module name)
  cmake_parse_arguments(M "" "" "PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  file(GLOB_RECURSE srcs CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/src/*.cpp)
  add_library(rtlab_${name} STATIC ${srcs})
  add_library(rtlab::${name} ALIAS rtlab_${name})
  set_target_properties(rtlab_${name} PROPERTIES EXPORT_NAME ${name})
  target_compile_features(rtlab_${name} PUBLIC cxx_std_20)
  target_include_directories(rtlab_${name} PUBLIC $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
                                                  $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_link_libraries(rtlab_${name} PUBLIC ${M_PUBLIC_DEPS} PRIVATE ${M_PRIVATE_DEPS})
  install(TARGETS rtlab_${name} EXPORT rtlabTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
  install(DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endfunction()
