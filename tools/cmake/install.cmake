# The installable package: `cmake --install build --prefix P` puts the libraries in P/lib, the
# public headers in P/include/tfmatch/<layer>/ (engine, shaders, kernels, model, reference,
# selftest, solvers, io, report, cuda: an embedder writes #include <tfmatch/engine/context.h>),
# the `tfmatch` program in P/bin, its netCDF-4 probe in P/libexec/tfmatch, and P/lib/cmake/tfmatch/tfmatchConfig.cmake (+ version file) and
# P/lib/pkgconfig/tfmatch.pc.
#   tfmatch::tfmatch  engine, shaders, kernels, host/model, host/reference, host/solvers:
#                     Vulkan headers, Eigen and GLM only (volk is compiled in under private names)
#   tfmatch::io       file formats (netCDF-C, ecCodes, expat, zlib) on host/model alone: no
#                     Vulkan, no engine (a program that only reads files links no GPU code)
#   tfmatch::report   images on disk, plots, metrics, report pages (libpng), with tfmatch::io
#   tfmatch::cuda     the CUDA solvers (find_package(tfmatch COMPONENTS cuda); built with
#                     TFMATCH_CUDA only): their own export set; they load the plugin
#                     P/lib/tfmatch/libtfmatch_cuda.so on first use, so nothing links CUDA
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(tfm_install_include ${CMAKE_INSTALL_INCLUDEDIR}/tfmatch)
set(tfm_layer_libraries tfmatch_model tfmatch_engine tfmatch_shaders tfmatch_kernels tfmatch_reference
    tfmatch_selftest tfmatch_solvers tfmatch_io tfmatch_report)
set(tfm_cuda_libraries)
if(TFMATCH_CUDA)
  set(tfm_cuda_libraries tfmatch_cuda_solvers)
  set_target_properties(tfmatch_cuda_solvers PROPERTIES EXPORT_NAME cuda)
endif()
# Header folders: those of tools/cmake/include_tree.cmake but the program's own layers (mpi,
# viewer) and, without TFMATCH_CUDA, cuda. Headers include each other by their layer-qualified
# names ("tfmatch/model/camera.h"), so <prefix>/include is the one folder on an embedder's include
# path, and a host header of the same bare name cannot be picked instead of one of ours.
set(tfm_header_layers ${TFMATCH_HEADER_FOLDERS})
list(FILTER tfm_header_layers EXCLUDE REGEX "^(mpi|viewer):")
if(NOT TFMATCH_CUDA)
  list(FILTER tfm_header_layers EXCLUDE REGEX "^cuda:")
endif()
set(tfm_install_include_dirs $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
set(tfm_pc_include_flags "-I\${includedir}")
foreach(lib ${tfm_layer_libraries})
  string(REPLACE "tfmatch_" "" short ${lib})
  set_target_properties(${lib} PROPERTIES EXPORT_NAME ${short})
endforeach()
foreach(lib ${tfm_layer_libraries} ${tfm_cuda_libraries})
  target_include_directories(${lib} INTERFACE ${tfm_install_include_dirs})
endforeach()

# The umbrella targets users link.
add_library(tfmatch_library INTERFACE)
set_target_properties(tfmatch_library PROPERTIES EXPORT_NAME tfmatch)
target_link_libraries(tfmatch_library INTERFACE tfmatch_solvers tfmatch_selftest)
# tfmatch_io and tfmatch_report export as tfmatch::io and tfmatch::report (their EXPORT_NAMEs).
# The same names inside this build (tests, examples built in-tree).
add_library(tfmatch::tfmatch ALIAS tfmatch_library)
add_library(tfmatch::io ALIAS tfmatch_io)
add_library(tfmatch::report ALIAS tfmatch_report)

install(TARGETS ${tfm_layer_libraries} tfmatch_library
        EXPORT tfmatchTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
if(TFMATCH_CUDA)
  install(TARGETS ${tfm_cuda_libraries} EXPORT tfmatchCudaTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
  install(TARGETS tfmatch_cuda LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}/tfmatch)  # the plugin
  install(EXPORT tfmatchCudaTargets NAMESPACE tfmatch:: DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/tfmatch)
endif()
if(TFMATCH_BUILD_PROGRAM)
  install(TARGETS tfmatch RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()
install(TARGETS tfmatch-netcdf4-probe RUNTIME DESTINATION ${CMAKE_INSTALL_LIBEXECDIR}/tfmatch)

# Public headers: every header of the library layers but the internal ones, which stay in the
# source tree: those named *_private.h or listed in TFMATCH_PRIVATE_HEADERS by their layer, and
# the helpers shared by one layer's sources only (no public header includes them; the package
# test compiles every installed header).
set(tfm_internal_headers ${TFMATCH_PRIVATE_HEADERS} ${CMAKE_SOURCE_DIR}/host/selftest/selftest_support.h
    ${CMAKE_SOURCE_DIR}/host/solvers/solver_support.h)
foreach(entry ${tfm_header_layers})
  string(REGEX REPLACE ":.*" "" folder ${entry})
  string(REGEX REPLACE "^[^:]*:" "" source ${entry})
  file(GLOB headers ${CMAKE_SOURCE_DIR}/${source}/*.h)
  list(FILTER headers EXCLUDE REGEX "_private\\.h$")
  foreach(internal ${tfm_internal_headers})
    list(REMOVE_ITEM headers ${internal})
  endforeach()
  install(FILES ${headers} DESTINATION ${tfm_install_include}/${folder})
endforeach()

install(EXPORT tfmatchTargets NAMESPACE tfmatch:: DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/tfmatch)
configure_package_config_file(${CMAKE_SOURCE_DIR}/tools/cmake/tfmatchConfig.cmake.in
                              ${CMAKE_BINARY_DIR}/tfmatchConfig.cmake
                              INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/tfmatch)
write_basic_package_version_file(${CMAKE_BINARY_DIR}/tfmatchConfigVersion.cmake COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/tfmatchConfig.cmake ${CMAKE_BINARY_DIR}/tfmatchConfigVersion.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/tfmatch)

# pkg-config, for builds without CMake: the core package (static libraries, in link order).
# The prefix is found from the .pc file's own place, so `cmake --install --prefix P` gives a
# correct file for any P (CMAKE_INSTALL_PREFIX at configure time may be another directory).
file(RELATIVE_PATH tfm_pc_up /prefix/${CMAKE_INSTALL_LIBDIR}/pkgconfig /prefix)
set(tfm_pc_libs
    "-ltfmatch_selftest -ltfmatch_solvers -ltfmatch_reference -ltfmatch_kernels -ltfmatch_shaders -ltfmatch_engine -ltfmatch_model")
configure_file(${CMAKE_SOURCE_DIR}/tools/cmake/tfmatch.pc.in ${CMAKE_BINARY_DIR}/tfmatch.pc @ONLY)
install(FILES ${CMAKE_BINARY_DIR}/tfmatch.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
