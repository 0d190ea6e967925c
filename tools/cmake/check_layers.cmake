# The layer rule of DESIGN.md, checked on every configure (and by the ctest test `Layers`):
# engine -> shaders -> kernels -> host/core -> host/reference -> host/solvers -> host/io ->
# host/report -> host/viewer -> tools. A file may include headers of its own layer and of layers before it,
# never one after it. Run as a script: cmake -DTFMATCH_SOURCE_DIR=<repo> -P check_layers.cmake
# (exit code 1 and one line per offending include). cuda/ sits beside kernels: it may use
# engine, shaders, kernels and host/core (field_mapping.h), and only host/solvers uses it.

cmake_policy(SET CMP0057 NEW)
set(layers engine shaders kernels cuda host/core host/reference host/selftest host/solvers host/io host/report host/viewer
    tools)
# cuda may include host/core's field_mapping.h (an inline mirror of the shader arithmetic).
set(allowed_exceptions "cuda:host/core/field_mapping.h")

# Which layer owns each header name (basenames are unique across the tree; a duplicate is an
# error too, because quoted includes resolve by name through the include path).
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
    file(STRINGS ${TFMATCH_SOURCE_DIR}/${source} includes REGEX "^[ \t]*#[ \t]*include[ \t]+\"[^\"]+\"")
    foreach(line ${includes})
      string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]+\"([^\"]+)\".*$" "\\1" target "${line}")
      get_filename_component(name ${target} NAME)
      if(NOT DEFINED owner_${name})
        continue()  # generated (build dir) or system header
      endif()
      if(owner_${name} GREATER rank_${layer})
        if(NOT "${layer}:${path_${name}}" IN_LIST allowed_exceptions)
          list(APPEND problems "${source} (${layer}) includes ${path_${name}} (${layer_of_${name}}, a later layer)")
        endif()
      endif()
    endforeach()
  endforeach()
endforeach()

if(problems)
  list(JOIN problems "\n  " text)
  message(FATAL_ERROR "layer rule broken (DESIGN.md: engine -> shaders -> kernels -> host -> tools):\n  ${text}")
endif()
message(STATUS "layers: every include points to the same or an earlier layer")
