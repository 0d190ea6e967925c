// tfmatch's TF JSON format: {"rgba": [[r,g,b,a], ...], "range": [lo, hi]?, "colorspace":
// "linear-rgb" (the default) | "srgb"?}.
#include "tfmatch/io/tf_json.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>
#include <stdexcept>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/model/color_spaces.h"

namespace tfm {

TransferFunction parse_tf_json(const std::string& text, const std::string& source) {
  nlohmann::json doc;
  // The table's own keys once each: the JSON parser keeps the last of two "rgba" arrays, and
  // which one a person meant is not for tfmatch to guess.
  std::string repeated;
  std::set<std::string> keys;
  const nlohmann::json::parser_callback_t once = [&](int depth, nlohmann::json::parse_event_t event,
                                                     nlohmann::json& parsed) {
    if (depth == 1 && event == nlohmann::json::parse_event_t::key && !keys.insert(parsed.get<std::string>()).second &&
        repeated.empty())
      repeated = parsed.get<std::string>();
    return true;
  };
  try {
    doc = nlohmann::json::parse(text, once);
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(source + ": not valid JSON (" + e.what() + ")");
  }
  if (!repeated.empty()) throw std::runtime_error(source + ": the key \"" + repeated + "\" appears more than once");
  if (!doc.is_object() || !doc.contains("rgba") || !doc["rgba"].is_array())
    throw std::runtime_error(source + ": expected an object with an \"rgba\" array of [r,g,b,a] rows");
  // Tables are linear RGB (docs/formats.md); a table declared sRGB is converted entry by entry.
  bool srgb = false;
  if (doc.contains("colorspace")) {
    const auto& space = doc["colorspace"];
    srgb = space == "srgb";
    if (!srgb && space != "linear-rgb")
      throw std::runtime_error(source + ": unknown \"colorspace\" " + space.dump() + " (linear-rgb, the default, or srgb)");
  }
  TransferFunction tf;
  size_t row = 0;
  for (const auto& e : doc["rgba"]) {
    if (!e.is_array() || e.size() != 4)
      throw std::runtime_error(source + ": rgba row " + std::to_string(row) + " is not 4 numbers");
    Rgba v;
    for (int c = 0; c < 4; ++c) {
      if (!e[c].is_number())
        throw std::runtime_error(source + ": rgba row " + std::to_string(row) + " has a non-number");
      v[c] = e[c].get<double>();
      if (!std::isfinite(v[c]) || v[c] < 0.0 || v[c] > 1.0)
      {
        // Ten digits: 1.0000001 and -1e-09 as such (std::to_string showed 1.000000 and -0.000000).
        std::ostringstream value;
        value << std::setprecision(10) << v[c];
        throw std::runtime_error(source + ": rgba row " + std::to_string(row) + " has value " + value.str() +
                                 " outside [0,1]");
      }
    }
    if (srgb)
      for (int c = 0; c < 3; ++c) v[c] = srgb_to_linear(v[c]);
    tf.rgba.push_back(v);
    ++row;
  }
  if (tf.rgba.size() < 2)
    throw std::runtime_error(source + ": a transfer function needs at least 2 entries, found " +
                             std::to_string(tf.rgba.size()));
  if (doc.contains("range")) {
    const auto& r = doc["range"];
    if (!r.is_array() || r.size() != 2 || !r[0].is_number() || !r[1].is_number() ||
        !(r[1].get<double>() > r[0].get<double>()))
      throw std::runtime_error(source + ": \"range\" must be [lo, hi] with lo < hi");
    tf.range = FieldRange{r[0].get<double>(), r[1].get<double>()};
  }
  return tf;
}

TransferFunction read_tf_json(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path.string() + ": cannot open transfer function file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_tf_json(ss.str(), path.string());
}

std::string tf_to_json(const TransferFunction& tf) {
  nlohmann::json doc;
  doc["format"] = "tfmatch-tf";
  doc["colorspace"] = "linear-rgb";
  auto rows = nlohmann::json::array();
  for (const Rgba& e : tf.rgba) rows.push_back({e[0], e[1], e[2], e[3]});
  doc["rgba"] = rows;
  if (tf.range) doc["range"] = {tf.range->lo, tf.range->hi};
  return doc.dump(1) + "\n";
}

void write_tf_json(const std::filesystem::path& path, const TransferFunction& tf) {
  write_file_atomically(path, tf_to_json(tf));
}
}  // namespace tfm
