// libFuzzer target: VTK XML ImageData parser (expat, base64, zlib blocks, appended data).
#include <stdexcept>

#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  static const char* const kSelections[] = {"", "b", "a[1]", "c", "x"};
  tfm::VolumeOptions options;
  options.variable = size ? kSelections[data[size - 1] % 5] : "";
  try {
    tfm::parse_vti(bytes, "fuzz.vti", options);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
