// Built-in transfer functions: names and options, opacity shapes, tables from colormap_tables.
#include "tfmatch/model/builtin_tf.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <iomanip>
#include <span>
#include <sstream>
#include <stdexcept>

#include "tfmatch/model/color_spaces.h"
#include "tfmatch/model/colormap_tables.h"

namespace tfm {
namespace {

struct MapInfo {
  const char* name;
  const char* source;
  std::span<const ColorStop> (*stops)();
  OpacityShape opacity;
};

// Diverging maps default to vee: their centre is the "nothing there" colour, so it should be
// transparent, and both ends are the values of interest.
const MapInfo kMaps[] = {
    {"viridis", "matplotlib's viridis (van der Walt & Smith)", viridis_srgb_stops, OpacityShape::Ramp},
    {"inferno", "matplotlib's inferno (van der Walt & Smith)", inferno_srgb_stops, OpacityShape::Ramp},
    {"cool-warm", "Moreland's cool-warm diverging map (2009)", cool_warm_srgb_stops, OpacityShape::Vee},
    {"grey", "a grey ramp, black to white in equal sRGB steps", grey_srgb_stops, OpacityShape::Ramp},
    {"diverging", "ColorBrewer RdBu, blue (low) through white to red (high)", rdbu_reversed_srgb_stops,
     OpacityShape::Vee},
};

const MapInfo* find_map(std::string_view name) {
  for (const MapInfo& m : kMaps)
    if (name == m.name) return &m;
  return nullptr;
}

const MapInfo& require_map(const std::string& name) {
  const MapInfo* m = find_map(name);
  if (!m) throw std::invalid_argument("'" + name + "' is not a built-in transfer function (" + builtin_tf_syntax() + ")");
  return *m;
}

std::string lower(std::string_view text) {
  std::string out(text);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return out;
}

}  // namespace

const std::vector<std::string>& builtin_tf_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> v;
    for (const MapInfo& m : kMaps) v.push_back(m.name);
    return v;
  }();
  return names;
}

std::string builtin_tf_syntax() {
  std::string out;
  const auto& names = builtin_tf_names();
  for (size_t i = 0; i < names.size(); ++i) out += (i == 0 ? "" : i + 1 == names.size() ? " or " : ", ") + names[i];
  return out + ", optionally NAME,opacity=ramp|flat|tent|vee";
}

const char* opacity_shape_name(OpacityShape shape) {
  switch (shape) {
    case OpacityShape::Ramp: return "ramp";
    case OpacityShape::Flat: return "flat";
    case OpacityShape::Tent: return "tent";
    case OpacityShape::Vee: return "vee";
  }
  return "ramp";
}

double opacity_at(OpacityShape shape, double t) {
  t = std::clamp(t, 0.0, 1.0);
  switch (shape) {
    case OpacityShape::Ramp: return t;
    case OpacityShape::Flat: return kFlatOpacity;
    case OpacityShape::Tent: return 1.0 - std::abs(2.0 * t - 1.0);
    case OpacityShape::Vee: return std::abs(2.0 * t - 1.0);
  }
  return t;
}

OpacityShape default_opacity_shape(const std::string& name) { return require_map(name).opacity; }

std::string builtin_tf_source(const std::string& name) { return require_map(name).source; }

std::optional<BuiltinTf> parse_builtin_tf(std::string_view text) {
  const std::string spec = lower(text);
  const size_t comma = spec.find(',');
  const MapInfo* map = find_map(std::string_view(spec).substr(0, comma));
  if (!map) return std::nullopt;
  BuiltinTf tf{map->name, map->opacity};
  if (comma == std::string::npos) return tf;
  const std::string option = spec.substr(comma + 1);
  const std::string key = "opacity=";
  if (option.rfind(key, 0) == 0) {
    const std::string shape = option.substr(key.size());
    for (OpacityShape s : {OpacityShape::Ramp, OpacityShape::Flat, OpacityShape::Tent, OpacityShape::Vee})
      if (shape == opacity_shape_name(s)) {
        tf.opacity = s;
        return tf;
      }
  }
  throw std::invalid_argument(std::string(text) + ": after the built-in name '" + map->name +
                              "' expected ,opacity=ramp|flat|tent|vee, got '," + std::string(text.substr(comma + 1)) + "'");
}

TransferFunction builtin_transfer_function(const BuiltinTf& tf, size_t n) {
  if (n < 2 || n > (size_t(1) << 16))
    throw std::invalid_argument("built-in transfer function: " + std::to_string(n) + " entries (2 to 65536)");
  const MapInfo& map = require_map(tf.name);
  // Blended in sRGB, where the published points are meant to be joined, then stored linear.
  TransferFunction out =
      tf_from_color_stops(uint32_t(n), map.stops(), [shape = tf.opacity](double t) { return opacity_at(shape, t); });
  for (Rgba& e : out.rgba) {
    const Rgb linear = srgb_to_linear(Rgb{e[0], e[1], e[2]});
    e = {linear[0], linear[1], linear[2], e[3]};
  }
  return out;
}

BuiltinTf default_builtin_tf(const FieldRange& range) {
  const char* name = range.lo < 0.0 && range.hi > 0.0 ? "diverging" : "viridis";
  return {name, default_opacity_shape(name)};
}

bool diverging_builtin_tf(const std::string& name) { return name == "diverging" || name == "cool-warm"; }

std::string diverging_middle_note(const BuiltinTf& tf, const FieldRange& range, const std::string& range_flag) {
  if (!diverging_builtin_tf(tf.name) || !(range.lo < 0.0 && range.hi > 0.0)) return {};
  const double middle = 0.5 * (range.lo + range.hi);
  if (std::abs(middle) <= 1e-3 * (range.hi - range.lo)) return {};
  const double m = std::max(-range.lo, range.hi);
  std::ostringstream os;
  os << std::setprecision(6) << "the built-in '" << tf.name << "' is laid over [" << range.lo << ", " << range.hi
     << "], so its neutral middle lies at " << middle << ", not at 0; " << range_flag << " " << -m << "," << m
     << " centres it on 0";
  return os.str();
}

}  // namespace tfm
