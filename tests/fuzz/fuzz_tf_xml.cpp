// libFuzzer target: the framework's XML transfer functions, through to the node-aligned table.
#include <cmath>
#include <cstdlib>
#include <stdexcept>

#include "tfmatch/io/tf_formats.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    tfm::ControlPointTf cp = tfm::parse_tf_xml(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.xml");
    tfm::TransferFunction tf = tfm::table_from_control_points(cp);
    for (const auto& e : tf.rgba)
      for (double c : e)
        if (!(c >= 0.0 && c <= 1.0)) std::abort();  // every table entry must be a valid colour
    tfm::parse_tf_xml(tfm::tf_to_xml(tf), "round trip");
  } catch (const std::runtime_error&) {
  }
  return 0;
}
