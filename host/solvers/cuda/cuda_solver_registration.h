// The optional CUDA solvers `cuda-normal-equations` and `cuda-cgls` (the package's `cuda`
// component: find_package(tfmatch COMPONENTS cuda), target tfmatch::cuda). A program that wants
// them calls register_cuda_solvers() once before it first asks the registry (solvers(),
// find_solver(), ...); tfmatch::tfmatch alone neither lists them nor links CUDA.
#pragma once

namespace tfm {

// Adds the CUDA solvers to the registry (add_solvers in solver.h); std::logic_error once the
// registry was built or when called twice. Touches no CUDA device: they throw on use without one.
void register_cuda_solvers();

}  // namespace tfm
