# Links follow the layer rule of DESIGN.md as includes do (tools/cmake/check_layers.cmake): a
# library of one layer links libraries of earlier layers only. Checked at configure time.
set(tfm_layer_targets tfmatch_engine tfmatch_shaders tfmatch_kernels tfmatch_core tfmatch_solvers tfmatch_io
    tfmatch_report tfmatch_viewer)
set(tfm_index 0)
foreach(target ${tfm_layer_targets})
  set(tfm_rank_${target} ${tfm_index})
  math(EXPR tfm_index "${tfm_index} + 1")
endforeach()
foreach(target ${tfm_layer_targets})
  get_target_property(deps ${target} LINK_LIBRARIES)
  foreach(dep ${deps})
    if(DEFINED tfm_rank_${dep} AND tfm_rank_${dep} GREATER tfm_rank_${target})
      message(FATAL_ERROR "layer rule broken: ${target} links ${dep}, a later layer (DESIGN.md)")
    endif()
  endforeach()
endforeach()
# Includes: the same rule, file by file (also the ctest test `Layers.IncludesPointDown`).
execute_process(COMMAND ${CMAKE_COMMAND} -DTFMATCH_SOURCE_DIR=${CMAKE_SOURCE_DIR} -P
                        ${CMAKE_SOURCE_DIR}/tools/cmake/check_layers.cmake
                RESULT_VARIABLE tfm_layers_result)
if(NOT tfm_layers_result EQUAL 0)
  message(FATAL_ERROR "layer rule broken (see above)")
endif()
