// libFuzzer target: the .dat descriptor parser.
#include <stdexcept>

#include "tfmatch/io/volume_formats.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    tfm::parse_dat_descriptor(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.dat", false);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
