// libFuzzer target: PNG decoding through libpng's simplified API (host/report/png_io.h): the
// header checks against the file size and the memory budget, then decoding to 8-bit RGB.
#include <stdexcept>
#include <string_view>

#include "fuzz_support.h"
#include "tfmatch/report/png_io.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  tfm::fuzz::limit_memory();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    const tfm::Image image = tfm::decode_png(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.png");
    // What readers rely on: the pixel buffer matches the size.
    if (image.rgb.size() != size_t(image.width) * image.height * 3) __builtin_trap();
  } catch (const std::runtime_error&) {
  }
  return 0;
}
