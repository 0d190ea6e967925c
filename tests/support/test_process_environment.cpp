// The environment every test process runs in, set before main() (so before any thread exists)
// unless the caller's environment already sets the variable:
//   TFMATCH_VALIDATION=1         the Khronos validation layer on; any message fails the test
//   TFMATCH_PIPELINE_CACHE=...   the build's own pipeline cache, not the user's XDG one
//   TFMATCH_NETCDF4_PROBE=...    the build's netCDF-4 probe program (host/io/netcdf4_probe.h)
//   TFMATCH_CUDA_PLUGIN=...      the build's CUDA solvers' plugin (host/solvers/cuda/cuda_backend.h)
// Set here rather than as ctest's ENVIRONMENT property: gtest_discover_tests passes a property's
// list elements on as separate words, so only the first variable of a list would reach a test.
#include <cstdlib>

namespace {

bool set_test_environment() {
  setenv("TFMATCH_VALIDATION", "1", 0);
  setenv("TFMATCH_PIPELINE_CACHE", TFMATCH_BUILD_DIR "/pipeline-cache", 0);
  setenv("TFMATCH_NETCDF4_PROBE", TFMATCH_BUILD_DIR "/tfmatch-netcdf4-probe", 0);
#ifdef TFMATCH_HAVE_CUDA
  setenv("TFMATCH_CUDA_PLUGIN", TFMATCH_BUILD_DIR "/libtfmatch_cuda.so", 0);
#endif
  return true;
}

[[maybe_unused]] const bool environment_set = set_test_environment();

}  // namespace
