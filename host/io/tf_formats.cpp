// Transfer-function file formats of other tools (see tf_formats.h): control points <-> tables,
// the framework's XML, ParaView presets, and dispatch by content / extension.
#include "tfmatch/io/tf_formats.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/tf_json.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/xml_tree.h"
#include "tfmatch/model/builtin_tf.h"
#include "tfmatch/model/color_spaces.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {
namespace {

// The key of a preset tfmatch writes that says whether the TF has a range ([lo, hi], the points'
// span) or not (null).
constexpr const char* kTfmatchRangeKey = "tfmatchRange";
// And the size of the table it was written from: its nodes are among the points, so a table of
// that size reads back exactly (the points between the nodes are for ParaView's blending).
constexpr const char* kTfmatchTableSizeKey = "tfmatchTableSize";

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

// ParaView's (VTK's) piecewise segment: the midpoint moves where the value is halfway, the
// sharpness bends the segment from linear (0) towards a step (1) through a Hermite curve.
double shaped_segment(double y1, double y2, double x, double midpoint, double sharpness) {
  const double mid = std::clamp(midpoint, 1e-5, 1.0 - 1e-5);
  x = x < mid ? 0.5 * x / mid : 0.5 + 0.5 * (x - mid) / (1.0 - mid);
  if (sharpness > 0.99) return x < 0.5 ? y1 : y2;
  if (sharpness < 0.01) return (1 - x) * y1 + x * y2;
  const double e = 1.0 + 10.0 * sharpness;
  if (x < 0.5) x = 0.5 * std::pow(2 * x, e);
  else if (x > 0.5) x = 1.0 - 0.5 * std::pow(2 * (1 - x), e);
  const double xx = x * x, xxx = xx * x;
  const double h1 = 2 * xxx - 3 * xx + 1, h2 = -2 * xxx + 3 * xx, h3 = xxx - 2 * xx + x, h4 = xxx - xx;
  const double tangent = (1 - sharpness) * (y2 - y1);
  const double v = h1 * y1 + h2 * y2 + h3 * tangent + h4 * tangent;
  return std::clamp(v, std::min(y1, y2), std::max(y1, y2));
}

// Index k of the segment [k-1, k] holding t, with the weight of point k; points sorted.
template <class P>
std::pair<size_t, double> locate(const std::vector<P>& p, double t) {
  if (t <= p.front().position) return {0, 1.0};
  if (t >= p.back().position) return {p.size() - 1, 1.0};
  size_t k = 1;
  while (p[k].position < t) ++k;
  if (p[k].position == t) return {k, 1.0};
  return {k, (t - p[k - 1].position) / (p[k].position - p[k - 1].position)};
}

template <class P>
void sort_points(std::vector<P>& p) {
  for (auto& x : p) x.position = std::clamp(x.position, 0.0, 1.0);
  std::stable_sort(p.begin(), p.end(), [](const P& a, const P& b) { return a.position < b.position; });
}

double attr_number(const XmlElement& e, const char* key, const std::string& name) {
  const std::string* v = e.attribute(key);
  auto n = v ? parse_number(*v) : std::nullopt;
  if (!n || !std::isfinite(*n))
    throw std::runtime_error(name + ": line " + std::to_string(e.line) + ": <" + e.name + "> needs a finite number in '" + key +
                             "'" + (v ? ", found '" + *v + "'" : ""));
  return *n;
}

}  // namespace

TransferFunction table_from_control_points(const ControlPointTf& in, size_t n) {
  if (in.opacity.empty() || in.color.empty()) throw std::invalid_argument("table_from_control_points: no points");
  if (n == 0) n = auto_table_size(in);
  if (n < 2) throw std::invalid_argument("table_from_control_points: need at least 2 entries");
  ControlPointTf cp = in;
  sort_points(cp.opacity);
  sort_points(cp.color);
  TransferFunction tf;
  tf.range = cp.range;
  tf.rgba.resize(n);
  for (size_t j = 0; j < n; ++j) {
    const double t = double(j) / double(n - 1);
    auto [ko, wo] = locate(cp.opacity, t);
    const auto& o1 = cp.opacity[ko];
    const double a = wo == 1.0 ? o1.opacity
                               : shaped_segment(cp.opacity[ko - 1].opacity, o1.opacity, wo, cp.opacity[ko - 1].midpoint,
                                                cp.opacity[ko - 1].sharpness);
    auto [kc, wc] = locate(cp.color, t);
    Rgb srgb = wc == 1.0 ? cp.color[kc].srgb : interpolate_color(cp.color[kc - 1].srgb, cp.color[kc].srgb, wc, cp.interpolation);
    const Rgb lin = srgb_to_linear(srgb);
    for (int c = 0; c < 3; ++c) tf.rgba[j][c] = std::clamp(lin[c], 0.0, 1.0);
    tf.rgba[j][3] = std::clamp(a, 0.0, 1.0);
  }
  return tf;
}

ControlPointTf control_points_from_table(const TransferFunction& tf) {
  ControlPointTf cp;
  cp.interpolation = ColorInterpolation::LinearRgb;
  cp.range = tf.range;
  const size_t n = tf.size();
  for (size_t j = 0; j < n; ++j) {
    const double t = n > 1 ? double(j) / double(n - 1) : 0.0;
    cp.opacity.push_back({t, tf.rgba[j][3]});
    cp.color.push_back({t, linear_to_srgb(Rgb{tf.rgba[j][0], tf.rgba[j][1], tf.rgba[j][2]})});
  }
  return cp;
}

size_t auto_table_size(const ControlPointTf& cp) {
  std::vector<double> pos;
  for (const auto& p : cp.opacity) pos.push_back(std::clamp(p.position, 0.0, 1.0));
  for (const auto& p : cp.color) pos.push_back(std::clamp(p.position, 0.0, 1.0));
  auto on_grid = [&](size_t d) {
    for (double p : pos) {
      const double x = p * double(d);
      if (std::abs(x - std::round(x)) > 1e-6) return false;
    }
    return true;
  };
  for (size_t d = 1; d <= 4096; ++d)
    if (on_grid(d)) return d * ((255 + d - 1) / d) + 1;
  // A finer grid: a table written by tfmatch (--tf-size up to 65536) has its points at j/(n-1),
  // so the closest two points give d. Trying every d up to 65535 would cost d times the points.
  std::sort(pos.begin(), pos.end());
  pos.erase(std::unique(pos.begin(), pos.end()), pos.end());
  double gap = 1.0;
  for (size_t k = 1; k < pos.size(); ++k) gap = std::min(gap, pos[k] - pos[k - 1]);
  const double d = std::round(1.0 / gap);
  if (d > 4096 && d <= double(kMaxTableSize - 1) && on_grid(size_t(d))) return size_t(d) + 1;
  // On no grid: 256 entries, or 4 a point for many points (up to the largest table), so that a
  // table's detail is not lost between its points.
  return std::clamp<size_t>(4 * pos.size(), 256, kMaxTableSize);
}

ControlPointTf parse_tf_xml(std::string_view text, const std::string& name, std::vector<std::string>* notes) {
  auto root = parse_xml(text, name);
  if (root->name != "TransferFunction")
    throw std::runtime_error(name + ": the root element is <" + root->name + ">, not <TransferFunction>");
  ControlPointTf cp;
  // Points are sRGB unless the file says otherwise; blending defaults to sRGB (as the framework).
  const std::string* points_space = root->attribute("colorspace");
  const bool points_linear = points_space && *points_space == "Linear RGB";
  if (points_space && *points_space != "sRGB" && !points_linear)
    throw std::runtime_error(name + ": unknown colorspace '" + *points_space + "' (sRGB or Linear RGB)");
  const std::string* interp = root->attribute("interpolation_colorspace");
  if (!interp) interp = root->attribute("colorspace_interpolation");  // older files
  if (interp && *interp != "sRGB" && *interp != "Linear RGB")
    throw std::runtime_error(name + ": unknown interpolation_colorspace '" + *interp + "' (sRGB or Linear RGB)");
  cp.interpolation = interp && *interp == "Linear RGB" ? ColorInterpolation::LinearRgb : ColorInterpolation::SRgb;
  // Opacities and colours outside [0, 1] are clamped, as the paper's framework reads its files,
  // and a note says how many (tfmatch JSON and ParaView presets refuse them instead).
  size_t clamped = 0;
  const auto in_unit = [&clamped](double v) {
    clamped += v < 0.0 || v > 1.0;
    return std::clamp(v, 0.0, 1.0);
  };
  if (const XmlElement* ops = root->child("OpacityPoints"))
    for (const XmlElement* p : ops->children_named("OpacityPoint"))
      cp.opacity.push_back({attr_number(*p, "position", name), in_unit(attr_number(*p, "opacity", name))});
  if (const XmlElement* cps = root->child("ColorPoints")) {
    const std::string* mode = cps->attribute("color_data");
    const std::string m = mode ? *mode : "ubyte";
    double scale = m == "ubyte" ? 255.0 : m == "ushort" ? 65535.0 : m == "float" ? 1.0 : m == "float_255" ? 255.0 : 0.0;
    if (scale == 0.0) throw std::runtime_error(name + ": unknown color_data '" + m + "' (ubyte, ushort, float, float_255)");
    for (const XmlElement* p : cps->children_named("ColorPoint")) {
      ControlPointTf::ColorPoint c;
      c.position = attr_number(*p, "position", name);
      const char* keys[3] = {"r", "g", "b"};
      for (int i = 0; i < 3; ++i) c.srgb[i] = in_unit(attr_number(*p, keys[i], name) / scale);
      if (points_linear) c.srgb = linear_to_srgb(c.srgb);
      cp.color.push_back(c);
    }
  }
  if (clamped && notes)
    notes->push_back(name + ": " + std::to_string(clamped) + " opacity or colour value" + (clamped > 1 ? "s" : "") +
                     " outside [0,1] clamped to it");
  // Positions outside [0, 1] are clamped too (sort_points): points there collapse onto the ends.
  size_t outside = 0;
  for (const auto& p : cp.opacity) outside += p.position < 0.0 || p.position > 1.0;
  for (const auto& p : cp.color) outside += p.position < 0.0 || p.position > 1.0;
  if (outside && notes)
    notes->push_back(name + ": " + std::to_string(outside) + " point position" + (outside > 1 ? "s" : "") +
                     " outside [0,1] clamped to it (such points collapse onto the TF's ends)");
  if (cp.opacity.empty()) throw std::runtime_error(name + ": no <OpacityPoint> in <OpacityPoints>");
  if (cp.color.empty()) throw std::runtime_error(name + ": no <ColorPoint> in <ColorPoints>");
  auto lo = root->attribute("range_min"), hi = root->attribute("range_max");  // tfmatch's addition
  if (bool(lo) != bool(hi))  // half a range is a mistake, not no range
    throw std::runtime_error(name + ": " + (lo ? "range_min without range_max" : "range_max without range_min") +
                             " (give both, or neither for a TF without a range)");
  if (lo && hi) {
    auto a = parse_number(*lo), b = parse_number(*hi);
    if (!a || !b || !std::isfinite(*a) || !std::isfinite(*b) || !(*b > *a))
      throw std::runtime_error(name + ": range_min/range_max must be numbers with range_min < range_max");
    cp.range = FieldRange{*a, *b};
  }
  return cp;
}

std::string tf_to_xml(const TransferFunction& tf) {
  const ControlPointTf cp = control_points_from_table(tf);
  std::ostringstream os;
  os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
     << "<!-- tfmatch: " << tf.size() << " node-aligned entries; sRGB colours as floats, blended in linear RGB -->\n"
     << "<TransferFunction colorspace=\"sRGB\" interpolation_colorspace=\"Linear RGB\"";
  if (tf.range) os << " range_min=\"" << num(tf.range->lo) << "\" range_max=\"" << num(tf.range->hi) << "\"";
  os << ">\n    <OpacityPoints>\n";
  for (const auto& p : cp.opacity)
    os << "        <OpacityPoint position=\"" << num(p.position) << "\" opacity=\"" << num(p.opacity) << "\"/>\n";
  os << "    </OpacityPoints>\n    <ColorPoints color_data=\"float\">\n";
  for (const auto& p : cp.color)
    os << "        <ColorPoint position=\"" << num(p.position) << "\" r=\"" << num(p.srgb[0]) << "\" g=\"" << num(p.srgb[1])
       << "\" b=\"" << num(p.srgb[2]) << "\"/>\n";
  os << "    </ColorPoints>\n</TransferFunction>\n";
  return os.str();
}

ControlPointTf parse_paraview_preset(std::string_view text, const std::string& name, const std::string& preset,
                                     std::vector<std::string>* notes) {
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(name + ": not valid JSON (" + e.what() + ")");
  }
  const nlohmann::json* obj = nullptr;
  if (doc.is_array()) {
    std::string names, first;
    size_t count = 0;
    for (const auto& p : doc) {
      if (!p.is_object() || !p.contains("RGBPoints")) continue;
      const std::string n = p.contains("Name") && p["Name"].is_string() ? p["Name"].get<std::string>() : "";
      names += (names.empty() ? "" : ", ") + n;
      if (++count == 1) first = n;
      if (!obj && (preset.empty() || n == preset)) obj = &p;
    }
    if (!obj)
      throw std::runtime_error(name + (preset.empty() ? ": no preset with RGBPoints" : ": no preset named '" + preset + "' (presets: " + names + ")"));
    // Which of several was taken, and how to take another (the first was used without a word).
    if (preset.empty() && count > 1 && notes)
      notes->push_back(name + ": " + std::to_string(count) + " presets (" + names + "); using the first, '" + first +
                       "' (FILE:NAME picks one)");
  } else if (doc.is_object()) {
    obj = &doc;
  } else {
    throw std::runtime_error(name + ": expected a ParaView preset (an object or an array of objects)");
  }
  auto numbers = [&](const char* key, size_t per_point) {
    std::vector<double> v;
    if (!obj->contains(key)) return v;
    const auto& a = (*obj)[key];
    if (!a.is_array() || a.empty() || a.size() % per_point != 0)
      throw std::runtime_error(name + ": \"" + key + "\" must be an array of " + std::to_string(per_point) + " numbers per point");
    for (const auto& x : a) {
      if (!x.is_number() || !std::isfinite(x.get<double>())) throw std::runtime_error(name + ": \"" + key + "\" holds a non-number");
      v.push_back(x.get<double>());
    }
    return v;
  };
  const std::vector<double> rgb = numbers("RGBPoints", 4), pts = numbers("Points", 4);
  if (rgb.empty()) throw std::runtime_error(name + ": the preset has no \"RGBPoints\"");
  ControlPointTf cp;
  if (obj->contains("ColorSpace") && !(*obj)["ColorSpace"].is_string())
    throw std::runtime_error(name + ": \"ColorSpace\" must be a name such as \"RGB\" or \"Diverging\", not " +
                             (*obj)["ColorSpace"].dump());
  const std::string space = obj->contains("ColorSpace") ? (*obj)["ColorSpace"].get<std::string>() : "RGB";
  try {
    cp.interpolation = parse_paraview_color_space(space);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(name + ": " + e.what());
  }
  if (notes && space == "Lab/CIEDE2000") notes->push_back(name + ": ColorSpace Lab/CIEDE2000 is blended in plain Lab");
  double lo = rgb[0], hi = rgb[0];
  for (size_t i = 0; i < rgb.size(); i += 4) lo = std::min(lo, rgb[i]), hi = std::max(hi, rgb[i]);
  for (size_t i = 0; i < pts.size(); i += 4) lo = std::min(lo, pts[i]), hi = std::max(hi, pts[i]);
  if (!(hi > lo)) throw std::runtime_error(name + ": all points are at one position; a range needs two");
  if (!std::isfinite(hi - lo)) throw std::runtime_error(name + ": the points span more than a double can hold");
  auto in01 = [&](double v, const char* what) {
    if (v < 0.0 || v > 1.0) throw std::runtime_error(name + ": " + what + " " + num(v) + " outside [0,1]");
    return v;
  };
  for (size_t i = 0; i < rgb.size(); i += 4)
    cp.color.push_back({(rgb[i] - lo) / (hi - lo), {in01(rgb[i + 1], "colour"), in01(rgb[i + 2], "colour"), in01(rgb[i + 3], "colour")}});
  for (size_t i = 0; i < pts.size(); i += 4)
    cp.opacity.push_back({(pts[i] - lo) / (hi - lo), in01(pts[i + 1], "opacity"), in01(pts[i + 2], "midpoint"), in01(pts[i + 3], "sharpness")});
  if (cp.opacity.empty()) {
    cp.opacity = {{0.0, 0.0}, {1.0, 1.0}};
    if (notes) notes->push_back(name + ": the preset has no opacity \"Points\"; using a ramp from 0 to 1");
  }
  if (!(lo == 0.0 && hi == 1.0)) cp.range = FieldRange{lo, hi};
  // tfmatch's own key (ParaView ignores keys it does not know): the range stated, so a TF whose
  // range is [0, 1] is told apart from one without a range, which the points' span cannot say.
  // It is the range exactly as written (the points' span may differ from it by rounding).
  if (obj->contains(kTfmatchRangeKey)) {
    const nlohmann::json& r = (*obj)[kTfmatchRangeKey];
    const bool pair = r.is_array() && r.size() == 2 && r[0].is_number() && r[1].is_number();
    if (r.is_null())
      cp.range.reset();
    else if (pair && std::isfinite(r[0].get<double>()) && r[1].get<double>() > r[0].get<double>() &&
             std::isfinite(r[1].get<double>()))
      cp.range = FieldRange{r[0].get<double>(), r[1].get<double>()};
    else
      throw std::runtime_error(name + ": \"" + kTfmatchRangeKey + "\" must be null or [lo, hi] with lo < hi");
  }
  if (obj->contains(kTfmatchTableSizeKey)) {
    const nlohmann::json& k = (*obj)[kTfmatchTableSizeKey];
    if (!k.is_number_unsigned() || k.get<uint64_t>() < 2 || k.get<uint64_t>() > kMaxTableSize)
      throw std::runtime_error(name + ": \"" + kTfmatchTableSizeKey + "\" must be a whole number from 2 to " +
                               std::to_string(kMaxTableSize));
    cp.table_size = size_t(k.get<uint64_t>());
  }
  return cp;
}

namespace {

// How far ParaView's blend of a preset's sRGB values may stray from tfmatch's linear blend between
// a table's nodes, per channel (linear RGB): half a level of 8 bits.
constexpr double kPresetBlendTolerance = 1.0 / 512;

// Points per table interval for a preset: the fewest m = 2^i <= 256 such that blending the sRGB values of
// the interval cut in m equal pieces stays within kPresetBlendTolerance of the linear blend.
uint32_t preset_pieces(const Rgb& a, const Rgb& b) {
  auto lerp = [](const Rgb& x, const Rgb& y, double t) {
    return Rgb{x[0] + t * (y[0] - x[0]), x[1] + t * (y[1] - x[1]), x[2] + t * (y[2] - x[2])};
  };
  for (uint32_t m = 1;; m *= 2) {
    double worst = 0.0;
    for (uint32_t k = 0; k < m; ++k) {
      const Rgb p0 = lerp(a, b, double(k) / m), p1 = lerp(a, b, double(k + 1) / m);
      const Rgb s0 = linear_to_srgb(p0), s1 = linear_to_srgb(p1);
      for (double t : {0.25, 0.5, 0.75}) {
        const Rgb blended = srgb_to_linear(lerp(s0, s1, t)), exact = lerp(p0, p1, t);
        for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(blended[c] - exact[c]));
      }
    }
    if (worst <= kPresetBlendTolerance || m == 256) return m;
  }
}

}  // namespace

std::string tf_to_paraview_json(const TransferFunction& tf, const std::string& preset_name) {
  // Colours go out as sRGB with ColorSpace "RGB", which ParaView blends as sRGB values where
  // tfmatch blends linear ones: exact at the nodes, and points between the nodes where the two
  // blends part by more than kPresetBlendTolerance (a black-to-white table of two entries was
  // 0.29 off midway). "tfmatchTableSize" gives tfmatch back the table's own nodes.
  const size_t n = tf.size();
  const double lo = tf.range ? tf.range->lo : 0.0, hi = tf.range ? tf.range->hi : 1.0;
  nlohmann::json p;
  p["Name"] = preset_name;
  p["Creator"] = "tfmatch";
  p["ColorSpace"] = "RGB";
  p["NanColor"] = {0.0, 0.0, 0.0};
  p["NanOpacity"] = 0.0;
  auto rgb = nlohmann::json::array(), pts = nlohmann::json::array();
  auto point = [&](double t, const Rgb& linear, double opacity) {
    const double x = lo + t * (hi - lo);
    const Rgb srgb = linear_to_srgb(linear);
    for (double v : {x, srgb[0], srgb[1], srgb[2]}) rgb.push_back(v);
    for (double v : {x, opacity, 0.5, 0.0}) pts.push_back(v);
  };
  const auto colour = [&](size_t j) { return Rgb{tf.rgba[j][0], tf.rgba[j][1], tf.rgba[j][2]}; };
  for (size_t j = 0; j < n; ++j) {
    point(n > 1 ? double(j) / double(n - 1) : 0.0, colour(j), tf.rgba[j][3]);
    if (j + 1 == n) break;
    const uint32_t m = preset_pieces(colour(j), colour(j + 1));
    for (uint32_t k = 1; k < m; ++k) {
      const double f = double(k) / m;
      const Rgb c{colour(j)[0] + f * (colour(j + 1)[0] - colour(j)[0]), colour(j)[1] + f * (colour(j + 1)[1] - colour(j)[1]),
                  colour(j)[2] + f * (colour(j + 1)[2] - colour(j)[2])};
      point((double(j) + f) / double(n - 1), c, tf.rgba[j][3] + f * (tf.rgba[j + 1][3] - tf.rgba[j][3]));
    }
  }
  p["RGBPoints"] = rgb;
  p["Points"] = pts;
  p[kTfmatchRangeKey] = tf.range ? nlohmann::json{lo, hi} : nlohmann::json(nullptr);
  p[kTfmatchTableSizeKey] = n;
  return json_text(nlohmann::json::array({p}), 1) + "\n";
}

namespace {

// Before a JSON TF is parsed into a document: its nesting (outside strings) is at most what a TF
// needs, and the document's memory (about 16 bytes a value, as many values as bytes at most) is
// checked against the budget. A 60 MB file of nested brackets took the parser past 2.9 GB.
void check_json_shape(std::string_view text, const std::string& name) {
  constexpr int kMaxDepth = 8;  // tfmatch tables and ParaView presets nest 3 deep
  int depth = 0;
  bool in_string = false, escaped = false;
  for (char c : text) {
    if (in_string) {
      if (escaped) escaped = false;
      else if (c == '\\') escaped = true;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxDepth)
        throw std::runtime_error(name + ": JSON nested more than " + std::to_string(kMaxDepth) +
                                 " levels deep; a transfer function nests 3 (an object, its arrays, their rows)");
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  check_memory(uint64_t(text.size()) * 16, name + ": parsing " + std::to_string(text.size()) + " bytes of JSON");
}

}  // namespace

TransferFunction parse_transfer_function(std::string_view text, const std::string& name, const TfReadOptions& options,
                                         std::vector<std::string>* notes) {
  size_t p = 0;
  while (p < text.size() && std::isspace(static_cast<unsigned char>(text[p]))) ++p;
  // Skip a UTF-8 byte order mark.
  if (text.substr(p, 3) == "\xEF\xBB\xBF") p += 3;
  if (p == text.size()) throw std::runtime_error(name + ": empty transfer function file");
  // FILE:NAME picks a preset of a ParaView file; a file of one TF has none to pick.
  auto one_tf = [&](const char* what) {
    if (!options.preset.empty())
      throw std::runtime_error(name + ": ':" + options.preset + "' names a preset of a ParaView preset file, but this is " +
                               what + " of one transfer function");
  };
  if (text[p] == '<') {
    one_tf("an XML file");
    return table_from_control_points(parse_tf_xml(text, name, notes), options.table_size);
  }
  if (text[p] != '{' && text[p] != '[')
    throw std::runtime_error(name + ": not a transfer function (expected XML, tfmatch JSON or a ParaView preset)");
  check_json_shape(text.substr(p), name);
  if (text[p] == '{') {
    nlohmann::json doc = nlohmann::json::parse(text, nullptr, false);
    if (doc.is_discarded()) parse_tf_json(std::string(text), name);  // throws, saying where
    if (doc.contains("rgba")) {
      one_tf("a tfmatch JSON table");
      TransferFunction tf = parse_tf_json(std::string(text), name);
      return options.table_size ? tf.resampled(options.table_size) : tf;
    }
    // Neither kind: say which keys would make it one (it was called a preset without RGBPoints).
    if (doc.is_object() && !doc.contains("RGBPoints") && !doc.contains("Name") && !doc.contains("ColorSpace"))
      throw std::runtime_error(name + ": a JSON object with neither \"rgba\" (a tfmatch table) nor \"RGBPoints\" (a "
                               "ParaView preset): not a transfer function");
  }
  const ControlPointTf cp = parse_paraview_preset(text, name, options.preset, notes);
  return table_from_control_points(cp, options.table_size ? options.table_size : cp.table_size.value_or(0));
}

std::optional<BuiltinTf> builtin_tf_named_by(const std::string& spec) {
  std::error_code ec;
  // A file of that name is read as a file; a directory is not one (an output folder viridis/).
  if (spec.empty() || (std::filesystem::exists(spec, ec) && !std::filesystem::is_directory(spec, ec)))
    return std::nullopt;
  try {
    return parse_builtin_tf(spec);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(e.what());
  }
}

TransferFunction read_transfer_function(const std::filesystem::path& path_in, const TfReadOptions& options_in,
                                        std::vector<std::string>* notes) {
  std::filesystem::path path = path_in;
  TfReadOptions options = options_in;
  const std::string spec = path_in.string();
  if (const auto builtin = builtin_tf_named_by(spec)) {
    const size_t n = options.table_size ? options.table_size : kDefaultBuiltinTfSize;
    if (notes)
      notes->push_back(spec + ": the built-in " + builtin_tf_source(builtin->name) + ", " + std::to_string(n) +
                       " entries, opacity " + opacity_shape_name(builtin->opacity));
    return builtin_transfer_function(*builtin, n);
  }
  if (!std::filesystem::exists(path)) {
    auto colon = spec.rfind(':');
    if (colon != std::string::npos && colon > 0 && std::filesystem::exists(spec.substr(0, colon))) {
      path = spec.substr(0, colon);
      options.preset = spec.substr(colon + 1);
    } else {
      throw std::runtime_error(spec + ": no such file, nor a built-in transfer function (" + builtin_tf_syntax() + ")");
    }
  }
  std::error_code ec;
  if (std::filesystem::file_size(path, ec) > (uint64_t(64) << 20) && !ec)
    throw std::runtime_error(path.string() + ": too large for a transfer function file (over 64 MiB)");
  TransferFunction tf = parse_transfer_function(read_file_bytes(path), path.string(), options, notes);
  // A range the file gives maps the reference field as a user range would: check it here, where
  // the message can name the file.
  if (tf.range) check_range(*tf.range, path.string());
  // A table no kernel takes fails here, naming the file, in every command (convert-tf wrote it on).
  if (tf.size() > kMaxTableSize)
    throw std::runtime_error(path.string() + ": " + std::to_string(tf.size()) + " entries; transfer functions hold at most " +
                             std::to_string(kMaxTableSize));
  return tf;
}

void write_transfer_function(const std::filesystem::path& path, const TransferFunction& tf) {
  const std::string file = path.filename().string();
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".xml") return write_file_atomically(path, tf_to_xml(tf));
  // Extensions compare without case (commands.md), the two-part one too: NAME.PARAVIEW.JSON had
  // been written as a tfmatch table.
  std::string lower_file = file;
  std::transform(lower_file.begin(), lower_file.end(), lower_file.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (file.size() > 14 && lower_file.ends_with(".paraview.json"))
    return write_file_atomically(path, tf_to_paraview_json(tf, file.substr(0, file.size() - 14)));
  if (ext == ".json") return write_tf_json(path, tf);
  throw std::runtime_error(path.string() + ": unknown transfer function format '" + ext +
                           "' (.json tfmatch table, .xml framework XML, .paraview.json ParaView preset)");
}

}  // namespace tfm
