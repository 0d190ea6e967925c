// libFuzzer target: transfer-function files by content (tfmatch JSON, ParaView presets, XML).
#include <cstdlib>
#include <stdexcept>

#include "tfmatch/io/tf_formats.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    tfm::TransferFunction tf =
        tfm::parse_transfer_function(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.json");
    for (const auto& e : tf.rgba)
      for (double c : e)
        if (!(c >= 0.0 && c <= 1.0)) std::abort();
    tfm::parse_transfer_function(tfm::tf_to_paraview_json(tf, "rt"), "round trip");
  } catch (const std::runtime_error&) {
  }
  return 0;
}
