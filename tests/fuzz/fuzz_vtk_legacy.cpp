// libFuzzer target: legacy VTK parser; every input must parse or throw std::runtime_error.
#include <stdexcept>

#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  // The first byte picks an array selection, so name lookup and components are exercised too.
  static const char* const kSelections[] = {"", "vectors", "s[1]", "scalars", "[2]", "rho"};
  tfm::VolumeOptions options;
  options.variable = size ? kSelections[data[0] % 6] : "";
  try {
    tfm::parse_vtk_legacy(bytes, "fuzz.vtk", options);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
