// libFuzzer target: NRRD parser. Detached data files resolve to the input itself, so the
// multi-file paths (formats, LIST, skips, encodings) see arbitrary bytes too.
#include <stdexcept>

#include "tfmatch/io/volume_formats.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  int files = 0;
  auto loader = [&](const std::string&) -> std::string {
    if (++files > 64) throw std::runtime_error("too many data files for the fuzzer");
    return input;
  };
  try {
    tfm::parse_nrrd(input, "fuzz.nrrd", {}, loader);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
