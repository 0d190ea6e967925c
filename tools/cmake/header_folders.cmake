# The folder every library layer's headers have under tfmatch/ (tools/cmake/include_tree.cmake in
# the build tree, tools/cmake/install.cmake in the install; tools/cmake/check_layers.cmake checks
# includes name it): "<folder>:<source folder>". The CUDA solvers' two source folders share one
# (cuda/'s interface header and host/solvers/cuda's loader); mpi and viewer are the program's own
# and not installed.
set(TFMATCH_HEADER_FOLDERS engine:engine shaders:shaders kernels:kernels cuda:cuda model:host/model
    reference:host/reference io:host/io mpi:host/mpi selftest:host/selftest solvers:host/solvers
    cuda:host/solvers/cuda report:host/report viewer:host/viewer)
