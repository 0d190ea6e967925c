// The test program lists the CUDA solvers as the `tfmatch` program does (tools/cli/main.cpp): the
// optional component joins the solver registry before any test asks for it.
#ifdef TFMATCH_HAVE_CUDA
#include "tfmatch/cuda/cuda_solver_registration.h"

namespace {
// Static initialisation runs before main(), so before any test builds the registry.
[[maybe_unused]] const bool registered = (tfm::register_cuda_solvers(), true);
}  // namespace
#endif
