# ctest `Package.InstallBuildAndRunEmbedExample`: installs this build into a temporary prefix,
# checks that no installed library defines a global vk*/volk* symbol, builds
# tools/examples/embed out of tree against the installed package (find_package(tfmatch)) and runs
# it: the example adopts its own plain-loader Vulkan device and checks a GPU fit on the CPU. Then
# builds and runs tools/examples/renderer (tfmatch's fit recorded into a renderer's own frames) and
# tools/examples/read_volume, which links tfmatch::io alone, and checks that the GPU-free
# layers keep it free of GPU code: no engine library or Vulkan loader on its link line, no engine
# or Vulkan symbol in the program, no libvulkan among its shared libraries; it reads a NetCDF file
# of ../shared/data when there is one (else says it skipped that).
# Arguments: -DBUILD_DIR= -DSOURCE_DIR= -DWORK_DIR= -DGENERATOR= -DNM=

file(REMOVE_RECURSE ${WORK_DIR})
set(prefix ${WORK_DIR}/prefix)
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT result EQUAL 0)
    list(JOIN ARGN " " command)
    message(FATAL_ERROR "failed (${result}): ${command}\n${out}\n${err}")
  endif()
  set(run_output "${out}" PARENT_SCOPE)
endfunction()

# Configures the project in `source` against the installed package and builds it in `build`
# (extra arguments go to the build: --verbose prints the link lines); run_output: the build's output.
function(build_against_package source build)
  run(${CMAKE_COMMAND} -S ${source} -B ${build} -G ${GENERATOR} -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_BUILD_TYPE=Release)
  run(${CMAKE_COMMAND} --build ${build} ${ARGN})
  set(run_output "${run_output}" PARENT_SCOPE)
endfunction()

run(${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix})
# The netCDF-4 probe's program, where the installed `tfmatch` looks for it (host/io/netcdf4_probe.h).
if(NOT EXISTS ${prefix}/libexec/tfmatch/tfmatch-netcdf4-probe OR NOT EXISTS ${prefix}/bin/tfmatch)
  message(FATAL_ERROR "bin/tfmatch or libexec/tfmatch/tfmatch-netcdf4-probe not installed under ${prefix}")
endif()

# No installed library may define a global Vulkan or volk entry point: a host that uses the
# plain loader would call tfmatch's copy instead of the loader's.
file(GLOB_RECURSE libraries ${prefix}/lib*/*.a ${prefix}/lib*/*.so)
if(NOT libraries)
  message(FATAL_ERROR "no library installed under ${prefix}")
endif()
foreach(lib ${libraries})
  run(${NM} -g --defined-only ${lib})
  string(REGEX MATCHALL "[0-9a-fA-F]* [A-Z] (vk|volk)[A-Z][A-Za-z0-9_]*" leaked "${run_output}")
  if(leaked)
    list(JOIN leaked "\n  " text)
    message(FATAL_ERROR "${lib} defines global Vulkan symbols:\n  ${text}")
  endif()
endforeach()
list(LENGTH libraries count)
message(STATUS "${count} installed libraries define no global vk*/volk* symbol")

# Headers by layer, none flat, and every installed one compiles (its includes resolve among the
# installed headers: no public header includes an internal one, and none reaches another by a
# bare name that a host's header could take).
foreach(header engine/context.h kernels/gpu_voxel_ops.h kernels/recording.h model/volume.h solvers/normal_equations.h
               io/volume_io.h)
  if(NOT EXISTS ${prefix}/include/tfmatch/${header})
    message(FATAL_ERROR "header tfmatch/${header} not installed")
  endif()
endforeach()
file(GLOB flat ${prefix}/include/tfmatch/*.h)
foreach(internal engine/vk_dispatch.h selftest/selftest_support.h solvers/solver_support.h)
  if(EXISTS ${prefix}/include/tfmatch/${internal})
    list(APPEND flat ${internal})
  endif()
endforeach()
if(flat)
  message(FATAL_ERROR "headers installed flat or internal ones installed: ${flat}")
endif()
file(GLOB_RECURSE installed_headers RELATIVE ${prefix}/include ${prefix}/include/tfmatch/*.h)
set(all_headers_source "")
foreach(header ${installed_headers})
  string(APPEND all_headers_source "#include <${header}>\n")
endforeach()
file(WRITE ${WORK_DIR}/all_headers/all_headers.cpp "${all_headers_source}int main() { return 0; }\n")
# A host's own headers of the same names, first on its include path: every one is an #error, so a
# header of ours that reached another by bare name ("camera.h") would pick the host's and fail.
file(REMOVE_RECURSE ${WORK_DIR}/all_headers/host_headers)
foreach(header ${installed_headers})
  get_filename_component(name ${header} NAME)
  file(WRITE ${WORK_DIR}/all_headers/host_headers/${name} "#error \"the host's ${name}, not tfmatch's\"\n")
endforeach()
file(WRITE ${WORK_DIR}/all_headers/CMakeLists.txt "cmake_minimum_required(VERSION 3.20)
project(tfmatch_all_headers LANGUAGES CXX)
set(CMAKE_CXX_STANDARD 20)
find_package(tfmatch REQUIRED)
add_executable(all_headers all_headers.cpp)
target_include_directories(all_headers BEFORE PRIVATE \${CMAKE_CURRENT_SOURCE_DIR}/host_headers)
target_link_libraries(all_headers PRIVATE tfmatch::tfmatch tfmatch::io tfmatch::report)
# As a host that builds with -Werror sees them: not as system headers, whose warnings are hidden.
set_target_properties(all_headers PROPERTIES NO_SYSTEM_FROM_IMPORTED ON)
target_compile_options(all_headers PRIVATE -Wall -Wextra -Werror)
")
build_against_package(${WORK_DIR}/all_headers ${WORK_DIR}/all_headers/build)
list(LENGTH installed_headers header_count)
message(STATUS "${header_count} installed headers, by layer, compile together beside host headers of their names, "
               "without a warning under -Wall -Wextra")

# CUDA is the `cuda` component's alone: the main targets name no CUDA library. Where the package
# has it, a program asking for the component gets the CUDA solvers in the registry.
file(GLOB main_exports ${prefix}/lib*/cmake/tfmatch/tfmatchTargets*.cmake)
foreach(export ${main_exports})
  file(READ ${export} text)
  if(text MATCHES "CUDA::|cudart|cusparse")
    message(FATAL_ERROR "${export} names CUDA: tfmatch::tfmatch must not need it")
  endif()
endforeach()
if(EXISTS ${prefix}/lib/cmake/tfmatch/tfmatchCudaTargets.cmake)
  file(WRITE ${WORK_DIR}/cuda_component/main.cpp "#include <cstdio>
#include <stdexcept>
#include <tfmatch/cuda/cuda_backend.h>
#include <tfmatch/cuda/cuda_solver_registration.h>
#include <tfmatch/solvers/solver.h>
int main() {
  tfm::register_cuda_solvers();
  for (const auto& name : tfm::solver_names()) std::printf(\"%s\\n\", name.c_str());
  try {
    std::printf(\"plugin loaded, CUDA device: %d\\n\", int(tfm::cuda::backend(\"list_solvers\").device_available()));
  } catch (const std::runtime_error& e) {
    std::printf(\"%s\\n\", e.what());
    return 1;
  }
}
")
  file(WRITE ${WORK_DIR}/cuda_component/CMakeLists.txt "cmake_minimum_required(VERSION 3.20)
project(tfmatch_cuda_component LANGUAGES CXX)
set(CMAKE_CXX_STANDARD 20)
find_package(tfmatch REQUIRED COMPONENTS cuda)
add_executable(list_solvers main.cpp)
target_link_libraries(list_solvers PRIVATE tfmatch::cuda)
")
  build_against_package(${WORK_DIR}/cuda_component ${WORK_DIR}/cuda_component/build)
  # A program of the embedder's, elsewhere, names the installed plugin.
  run(${CMAKE_COMMAND} -E env TFMATCH_CUDA_PLUGIN=${prefix}/lib/tfmatch/libtfmatch_cuda.so
      ${WORK_DIR}/cuda_component/build/list_solvers)
  if(NOT run_output MATCHES "cuda-cgls" OR NOT run_output MATCHES "cuda-normal-equations"
     OR NOT run_output MATCHES "plugin loaded")
    message(FATAL_ERROR "the cuda component did not add the CUDA solvers or load the plugin:\n${run_output}")
  endif()
  message(STATUS "the cuda component adds the CUDA solvers to the registry and loads the installed plugin")
  # The installed program finds its plugin in ../lib/tfmatch by itself: a CUDA solver either runs
  # or says there is no CUDA device (not that the plugin is missing).
  execute_process(COMMAND ${CMAKE_COMMAND} -E env --unset=TFMATCH_CUDA_PLUGIN ${prefix}/bin/tfmatch demo --size 8
                          --solver cuda-cgls --no-report --out ${WORK_DIR}/cuda_demo
                  RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT result EQUAL 0 AND NOT err MATCHES "cuda-cgls: no CUDA device available")
    message(FATAL_ERROR "the installed tfmatch did not run cuda-cgls (${result}):\n${out}\n${err}")
  endif()
  message(STATUS "the installed tfmatch loads its CUDA plugin: ${result}")
else()
  message(STATUS "no cuda component in this package (built without TFMATCH_CUDA)")
endif()

# pkg-config (for builds without CMake) finds the headers and libraries where they were installed.
find_program(PKG_CONFIG pkg-config)
if(PKG_CONFIG)
  set(ENV{PKG_CONFIG_PATH} ${prefix}/lib/pkgconfig)
  run(${PKG_CONFIG} --cflags --libs tfmatch)
  file(REAL_PATH ${prefix} real_prefix)
  string(REGEX MATCH "-I([^ ]+)/include( |$)" include_flag "${run_output}")
  file(REAL_PATH "${CMAKE_MATCH_1}" pc_prefix)
  if(NOT pc_prefix STREQUAL real_prefix OR NOT run_output MATCHES "-ltfmatch_engine")
    message(FATAL_ERROR "tfmatch.pc does not point into ${prefix}: ${run_output}")
  endif()
else()
  message(STATUS "pkg-config not installed: tfmatch.pc not checked")
endif()

build_against_package(${SOURCE_DIR}/tools/examples/embed ${WORK_DIR}/example)
run(${WORK_DIR}/example/embed_example)
message(STATUS "${run_output}")
if(NOT run_output MATCHES "OK")
  message(FATAL_ERROR "the example did not report OK")
endif()

# The renderer that records tfmatch's fit into its own frames (tools/examples/renderer), with the
# validation layer and synchronization validation on where the layer is installed.
build_against_package(${SOURCE_DIR}/tools/examples/renderer ${WORK_DIR}/renderer)
if(EXISTS /usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json)
  set(ENV{TFMATCH_VALIDATION} 1)
endif()
run(${WORK_DIR}/renderer/renderer_example)
unset(ENV{TFMATCH_VALIDATION})
message(STATUS "${run_output}")
if(NOT run_output MATCHES "\nOK\n")
  message(FATAL_ERROR "the renderer example did not report OK")
endif()

build_against_package(${SOURCE_DIR}/tools/examples/read_volume ${WORK_DIR}/read_volume --verbose)
string(REGEX MATCHALL "[^ \n]*(tfmatch_engine|tfmatch_kernels|tfmatch_shaders|libvulkan|-lvulkan)[^ \n]*" linked "${run_output}")
if(linked)
  list(JOIN linked " " text)
  message(FATAL_ERROR "read_volume (tfmatch::io only) links GPU libraries: ${text}")
endif()
set(program ${WORK_DIR}/read_volume/read_volume)
run(${NM} -C ${program})
string(REGEX MATCHALL "[^\n]*(tfm::Context|tfm::Buffer|tfm_volk|vkCreateInstance|vkGetInstanceProcAddr)[^\n]*" symbols "${run_output}")
if(symbols)
  list(JOIN symbols "\n  " text)
  message(FATAL_ERROR "read_volume (tfmatch::io only) contains GPU code:\n  ${text}")
endif()
find_program(LDD ldd)
if(LDD)
  run(${LDD} ${program})
  if(run_output MATCHES "libvulkan")
    message(FATAL_ERROR "read_volume (tfmatch::io only) loads libvulkan:\n${run_output}")
  endif()
endif()
set(netcdf ${SOURCE_DIR}/../shared/data/cam_uvt/uvt.nc)
if(EXISTS ${netcdf})
  run(${program} ${netcdf}:U)
  message(STATUS "${run_output}")
  if(NOT run_output MATCHES "128 x 64 x 14.*OK")
    message(FATAL_ERROR "read_volume did not read ${netcdf}")
  endif()
else()
  message(STATUS "SKIPPED reading a NetCDF file with read_volume: ${netcdf} not found (no ../shared)")
endif()
file(REMOVE_RECURSE ${WORK_DIR})
