// libFuzzer target: GRIB 1 and 2 through ecCodes from memory (fmemopen), driving tfmatch's own
// code around the library: grouping messages by parameter and level type, levels, times and
// members, grid checks and the values' missing points; `tfmatch info`'s listing, then loading
// each parameter it lists with time and member indices 0 and 1.
#include <stdexcept>
#include <string>

#include "fuzz_support.h"
#include "volume_formats.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  tfm::fuzz::limit_memory();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);  // fmemopen wants a writable pointer
  tfm::FileInfo info;
  try {
    info = tfm::describe_grib_bytes(bytes, "fuzz.grib");
  } catch (const std::runtime_error&) {
    return 0;
  }
  tfm::fuzz::load_each_array(info, [&](const tfm::VolumeOptions& options) { tfm::parse_grib(bytes, "fuzz.grib", options); });
  return 0;
}
