// libFuzzer target: GRIB 1 and 2 through ecCodes from memory (fmemopen), driving tfmatch's own
// code around the library: grouping messages by parameter and level type, levels, times and
// members, grid checks and the values' missing points; `tfmatch info`'s listing, then loading
// each parameter it lists with time and member indices 0 and 1.
#include "fuzz_support.h"
#include "tfmatch/io/volume_formats.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  tfm::fuzz::limit_memory();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tfm::fuzz::describe_then_load(
      data, size, [](const std::string& bytes) { return tfm::describe_grib_bytes(bytes, "fuzz.grib"); },
      [](const std::string& bytes, const tfm::VolumeOptions& options) { tfm::parse_grib(bytes, "fuzz.grib", options); });
  return 0;
}
