# Every include of a library header names its layer, as an embedder writes it against the
# installed package: #include "tfmatch/model/camera.h", never "camera.h". A bare name resolves
# through the include path, so a host with its own camera.h earlier on that path would have broken
# <tfmatch/kernels/recording.h>. In the build tree the same names resolve through
# <build>/include/tfmatch/<folder>/<header>, links to the headers where they live; the install
# copies them to <prefix>/include/tfmatch/<folder>/ (tools/cmake/install.cmake), and
# tools/cmake/check_layers.cmake refuses a bare include of a library header.
include(${CMAKE_CURRENT_LIST_DIR}/header_folders.cmake)
set(TFMATCH_INCLUDE_ROOT ${CMAKE_BINARY_DIR}/include)

# Links rather than copies, so an edited header needs no configure step; a header added or
# removed reconfigures (CONFIGURE_DEPENDS) and its link follows.
set(tfm_links)
foreach(entry ${TFMATCH_HEADER_FOLDERS})
  string(REGEX REPLACE ":.*" "" folder ${entry})
  string(REGEX REPLACE "^[^:]*:" "" source ${entry})
  file(GLOB headers CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/${source}/*.h ${CMAKE_SOURCE_DIR}/${source}/*.cuh)
  foreach(header ${headers})
    get_filename_component(name ${header} NAME)
    set(link ${TFMATCH_INCLUDE_ROOT}/tfmatch/${folder}/${name})
    list(APPEND tfm_links ${link})
    set(target "")
    if(IS_SYMLINK ${link})
      file(READ_SYMLINK ${link} target)
    endif()
    if(NOT target STREQUAL header)
      file(REMOVE ${link})
      file(MAKE_DIRECTORY ${TFMATCH_INCLUDE_ROOT}/tfmatch/${folder})
      file(CREATE_LINK ${header} ${link} SYMBOLIC)
    endif()
  endforeach()
endforeach()
# A header deleted from the tree must not go on resolving through a stale link.
file(GLOB_RECURSE existing LIST_DIRECTORIES false ${TFMATCH_INCLUDE_ROOT}/tfmatch/*)
foreach(link ${existing})
  if(NOT link IN_LIST tfm_links)
    file(REMOVE ${link})
  endif()
endforeach()
