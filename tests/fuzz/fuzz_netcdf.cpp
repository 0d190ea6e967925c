// libFuzzer target: NetCDF through netCDF-C from memory (nc_open_mem), driving tfmatch's own code
// around the library: the variable listing of `tfmatch info` (dimension roles, fill values,
// packing, coordinate spacing, ranges over every time and member), then loading each variable it
// lists with time and member indices 0 and 1.
#include <stdexcept>
#include <string>

#include "fuzz_support.h"
#include "volume_formats.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  tfm::fuzz::limit_memory();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);  // netCDF-C wants a writable pointer
  tfm::FileInfo info;
  try {
    info = tfm::describe_netcdf_bytes(bytes, "fuzz.nc");
  } catch (const std::runtime_error&) {
    return 0;
  }
  tfm::fuzz::load_each_array(info, [&](const tfm::VolumeOptions& options) { tfm::parse_netcdf(bytes, "fuzz.nc", options); });
  return 0;
}
