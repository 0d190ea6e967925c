# The layer rule of DESIGN.md, checked on every configure (and by the ctest test `Layers`):
# shaders -> host/model -> engine -> kernels -> cuda -> host/reference -> host/io -> host/mpi ->
# host/selftest -> host/solvers -> host/report -> host/viewer -> tools. A file may include headers
# of its own layer and of layers before it, never one after it. The shaders' layout headers are
# plain structs shared with GLSL, and the model is the GPU-free data every part shares, so both sit
# below the engine. The GPU-free layers (shaders' headers, host/model, host/reference, host/io,
# host/mpi) may include only each other: file formats, CPU references and the MPI ranks build
# without Vulkan and the engine.
# Run as a script: cmake -DTFMATCH_SOURCE_DIR=<repo> -P check_layers.cmake (exit code 1 and one
# line per offending include). cuda/ may use engine, shaders, kernels and host/model, and only
# host/solvers uses it. Every file, tests included, reads nlohmann::json through host/io/json.h.
# Every include of a library header names its folder (tools/cmake/header_folders.cmake):
# "tfmatch/model/camera.h", never "camera.h", which would resolve through the include path to
# whatever camera.h comes first there. The shaders' layout headers alone include each other by
# name: glslang reads them too, and a quoted name is found first beside the including file.

cmake_policy(SET CMP0057 NEW)
set(layers shaders host/model engine kernels cuda host/reference host/io host/mpi host/selftest host/solvers
    host/report host/viewer tools)
set(gpu_free_layers shaders host/model host/reference host/io host/mpi)
set(allowed_exceptions "")
include(${CMAKE_CURRENT_LIST_DIR}/header_folders.cmake)
foreach(entry ${TFMATCH_HEADER_FOLDERS})
  string(REGEX REPLACE ":.*" "" folder ${entry})
  string(REGEX REPLACE "^[^:]*:" "" source ${entry})
  set(folder_of_${source} ${folder})
endforeach()

# Which layer owns each header name (basenames are unique across the tree, a duplicate is an
# error: this check finds a header's layer by its name, and the cuda folder joins two source
# folders).
set(rank 0)
foreach(layer ${layers})
  file(GLOB_RECURSE headers RELATIVE ${TFMATCH_SOURCE_DIR} ${TFMATCH_SOURCE_DIR}/${layer}/*.h
       ${TFMATCH_SOURCE_DIR}/${layer}/*.cuh ${TFMATCH_SOURCE_DIR}/${layer}/*.glsl)
  foreach(header ${headers})
    get_filename_component(name ${header} NAME)
    if(DEFINED owner_${name})
      list(APPEND problems "${header}: header name also used by ${path_${name}}")
    endif()
    set(owner_${name} ${rank})
    set(path_${name} ${header})
    set(layer_of_${name} ${layer})
    get_filename_component(dir ${header} DIRECTORY)
    set(dir_of_${name} ${dir})
    set(spelling_of_${name} ${name})  # the program's own (tools/cli) include each other by name
    if(DEFINED folder_of_${dir})
      set(spelling_of_${name} tfmatch/${folder_of_${dir}}/${name})
    endif()
  endforeach()
  set(rank_${layer} ${rank})
  math(EXPR rank "${rank} + 1")
endforeach()

foreach(layer ${layers})
  file(GLOB_RECURSE sources RELATIVE ${TFMATCH_SOURCE_DIR} ${TFMATCH_SOURCE_DIR}/${layer}/*.h
       ${TFMATCH_SOURCE_DIR}/${layer}/*.cpp ${TFMATCH_SOURCE_DIR}/${layer}/*.cu ${TFMATCH_SOURCE_DIR}/${layer}/*.cuh
       ${TFMATCH_SOURCE_DIR}/${layer}/*.comp ${TFMATCH_SOURCE_DIR}/${layer}/*.glsl ${TFMATCH_SOURCE_DIR}/${layer}/*.in)
  foreach(source ${sources})
    # tools/examples are host programs built against the installed package: not a layer.
    if(source MATCHES "^tools/examples/")
      continue()
    endif()
    if(layer IN_LIST gpu_free_layers)
      file(STRINGS ${TFMATCH_SOURCE_DIR}/${source} gpu_includes REGEX "^[ \t]*#[ \t]*include[ \t]+<(vulkan|volk)")
      foreach(line ${gpu_includes})
        list(APPEND problems "${source} (${layer}, GPU-free) includes a Vulkan header: ${line}")
      endforeach()
    endif()
    file(STRINGS ${TFMATCH_SOURCE_DIR}/${source} includes REGEX "^[ \t]*#[ \t]*include[ \t]+\"[^\"]+\"")
    foreach(line ${includes})
      string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]+\"([^\"]+)\".*$" "\\1" target "${line}")
      get_filename_component(name ${target} NAME)
      if(NOT DEFINED owner_${name})
        continue()  # generated (build dir) or system header
      endif()
      get_filename_component(source_dir ${source} DIRECTORY)
      get_filename_component(source_ext ${source} LAST_EXT)
      if(NOT target STREQUAL spelling_of_${name}
         AND NOT (source_dir STREQUAL "shaders" AND dir_of_${name} STREQUAL "shaders" AND target STREQUAL name
                  AND source_ext MATCHES "^\\.(h|comp|glsl)$"))
        list(APPEND problems "${source} includes \"${target}\": write \"${spelling_of_${name}}\"")
      endif()
      if(owner_${name} GREATER rank_${layer})
        if(NOT "${layer}:${path_${name}}" IN_LIST allowed_exceptions)
          list(APPEND problems "${source} (${layer}) includes ${path_${name}} (${layer_of_${name}}, a later layer)")
        endif()
      elseif(layer IN_LIST gpu_free_layers AND NOT layer_of_${name} IN_LIST gpu_free_layers)
        list(APPEND problems "${source} (${layer}, GPU-free) includes ${path_${name}} (${layer_of_${name}}, a GPU layer)")
      endif()
    endforeach()
  endforeach()
endforeach()

# nlohmann::json comes through host/io/json.h everywhere, tests included: it defines JSON_ASSERT
# before the library, and one definition must hold in every file (see that header).
file(GLOB_RECURSE json_users RELATIVE ${TFMATCH_SOURCE_DIR} ${TFMATCH_SOURCE_DIR}/host/*.h ${TFMATCH_SOURCE_DIR}/host/*.cpp
     ${TFMATCH_SOURCE_DIR}/tools/*.h ${TFMATCH_SOURCE_DIR}/tools/*.cpp ${TFMATCH_SOURCE_DIR}/tests/*.h
     ${TFMATCH_SOURCE_DIR}/tests/*.cpp ${TFMATCH_SOURCE_DIR}/kernels/*.cpp ${TFMATCH_SOURCE_DIR}/engine/*.cpp)
foreach(source ${json_users})
  if(source STREQUAL "host/io/json.h")
    continue()
  endif()
  file(STRINGS ${TFMATCH_SOURCE_DIR}/${source} direct REGEX "^[ \t]*#[ \t]*include[ \t]+<nlohmann/json")
  if(direct)
    list(APPEND problems "${source} includes <nlohmann/json.hpp> directly, not \"tfmatch/io/json.h\"")
  endif()
endforeach()

if(problems)
  list(JOIN problems "\n  " text)
  message(FATAL_ERROR "layer rule broken (DESIGN.md; tools/cmake/check_layers.cmake):\n  ${text}")
endif()
message(STATUS "layers: every include points to the same or an earlier layer and names its folder")
