// libFuzzer target: NetCDF through netCDF-C from memory (nc_open_mem), driving tfmatch's own code
// around the library: the variable listing of `tfmatch info` (dimension roles, fill values,
// packing, coordinate spacing, ranges over every time and member), then loading each variable it
// lists with time and member indices 0 and 1.
#include "fuzz_support.h"
#include "tfmatch/io/volume_formats.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  tfm::fuzz::limit_memory();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tfm::fuzz::describe_then_load(
      data, size, [](const std::string& bytes) { return tfm::describe_netcdf_bytes(bytes, "fuzz.nc"); },
      [](const std::string& bytes, const tfm::VolumeOptions& options) { tfm::parse_netcdf(bytes, "fuzz.nc", options); });
  return 0;
}
