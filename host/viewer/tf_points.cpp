// Editor control points of a TF table, and back.
#include "tfmatch/viewer/tf_points.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

#include "tfmatch/model/color_spaces.h"

namespace tfm {
namespace {

// Greedy simplification of one curve sampled at table nodes (Douglas-Peucker's refinement order,
// without recursion): `values[j]` has `dim` components; returns the chosen node indices, ascending.
std::vector<size_t> simplify_nodes(const std::vector<std::array<double, 3>>& values, int dim, double tolerance,
                                   size_t max_points) {
  const size_t n = values.size();
  std::vector<size_t> chosen = {0, n - 1};
  while (chosen.size() < max_points) {
    double worst = tolerance;
    size_t worst_j = 0;
    for (size_t s = 0; s + 1 < chosen.size(); ++s) {
      const size_t a = chosen[s], b = chosen[s + 1];
      for (size_t j = a + 1; j < b; ++j) {
        const double w = double(j - a) / double(b - a);
        for (int c = 0; c < dim; ++c) {
          const double line = (1 - w) * values[a][size_t(c)] + w * values[b][size_t(c)];
          const double err = std::abs(line - values[j][size_t(c)]);
          if (err > worst) worst = err, worst_j = j;
        }
      }
    }
    if (worst_j == 0) break;  // every entry within tolerance
    chosen.insert(std::upper_bound(chosen.begin(), chosen.end(), worst_j), worst_j);
  }
  return chosen;
}

double number_in(const nlohmann::json& p, const char* key, const std::string& what) {
  if (!p.is_object() || !p.contains(key) || !p[key].is_number())
    throw std::invalid_argument(what + ": \"" + key + "\" must be a number");
  const double x = p[key].get<double>();
  if (!(x >= 0.0 && x <= 1.0)) throw std::invalid_argument(what + ": \"" + key + "\" must be in [0, 1]");
  return x;
}

Rgb parse_hex(const std::string& text, const std::string& what) {
  unsigned r = 0, g = 0, b = 0;
  char tail = 0;
  if (text.size() != 7 || text[0] != '#' ||
      std::sscanf(text.c_str() + 1, "%2x%2x%2x%c", &r, &g, &b, &tail) != 3 ||
      text.find_first_not_of("0123456789abcdefABCDEF", 1) != std::string::npos)
    throw std::invalid_argument(what + ": colour must be #rrggbb");
  return {r / 255.0, g / 255.0, b / 255.0};
}

void check_count(const nlohmann::json& list, const char* kind) {
  if (!list.is_array()) throw std::invalid_argument(std::string("\"") + kind + "\" must be a list of points");
  if (list.size() < 2 || list.size() > 256)
    throw std::invalid_argument(std::string(kind) + ": 2 to 256 points, not " + std::to_string(list.size()));
}

}  // namespace

std::string hex_color(const Rgb& srgb) {
  char buf[8];
  auto byte = [](double c) { return unsigned(std::lround(std::clamp(c, 0.0, 1.0) * 255.0)); };
  std::snprintf(buf, sizeof buf, "#%02x%02x%02x", byte(srgb[0]), byte(srgb[1]), byte(srgb[2]));
  return buf;
}

ControlPointTf editor_points(const TransferFunction& tf, size_t all_up_to, double tolerance, size_t max_points) {
  if (tf.size() < 2) throw std::invalid_argument("editor_points: a TF needs at least 2 entries");
  const size_t n = tf.size();
  std::vector<std::array<double, 3>> alpha(n), colour(n);
  for (size_t j = 0; j < n; ++j) {
    alpha[j] = {tf.rgba[j][3], 0, 0};
    colour[j] = {tf.rgba[j][0], tf.rgba[j][1], tf.rgba[j][2]};
  }
  std::vector<size_t> opacity_nodes, colour_nodes;
  if (n <= all_up_to) {
    for (size_t j = 0; j < n; ++j) opacity_nodes.push_back(j);
    colour_nodes = opacity_nodes;
  } else {
    opacity_nodes = simplify_nodes(alpha, 1, tolerance, std::max<size_t>(max_points, 2));
    colour_nodes = simplify_nodes(colour, 3, tolerance, std::max<size_t>(max_points, 2));
  }
  ControlPointTf cp;
  cp.interpolation = ColorInterpolation::LinearRgb;
  cp.range = tf.range;
  const double last = double(n - 1);
  for (size_t j : opacity_nodes) cp.opacity.push_back({double(j) / last, tf.rgba[j][3]});
  for (size_t j : colour_nodes)
    cp.color.push_back({double(j) / last, linear_to_srgb(Rgb{tf.rgba[j][0], tf.rgba[j][1], tf.rgba[j][2]})});
  return cp;
}

nlohmann::json editor_points_json(const ControlPointTf& cp) {
  nlohmann::json out = {{"opacity", nlohmann::json::array()}, {"color", nlohmann::json::array()}};
  for (const auto& p : cp.opacity) out["opacity"].push_back({{"x", p.position}, {"a", p.opacity}});
  for (const auto& p : cp.color)
    out["color"].push_back({{"x", p.position}, {"rgb", hex_color(p.srgb)}, {"srgb", p.srgb}});
  return out;
}

ControlPointTf parse_editor_points(const nlohmann::json& doc) {
  if (!doc.is_object() || !doc.contains("opacity") || !doc.contains("color"))
    throw std::invalid_argument("reference TF: expected {\"opacity\": [...], \"color\": [...]}");
  const nlohmann::json& opacity = doc["opacity"];
  const nlohmann::json& color = doc["color"];
  check_count(opacity, "opacity");
  check_count(color, "color");
  ControlPointTf cp;
  cp.interpolation = ColorInterpolation::LinearRgb;
  auto check_order = [](double x, double previous, const std::string& what) {
    if (x < previous) throw std::invalid_argument(what + ": positions must be ascending");
  };
  double previous = 0.0;
  for (size_t i = 0; i < opacity.size(); ++i) {
    const std::string what = "opacity point " + std::to_string(i + 1);
    const double x = number_in(opacity[i], "x", what);
    check_order(x, previous, what);
    cp.opacity.push_back({x, number_in(opacity[i], "a", what)});
    previous = x;
  }
  previous = 0.0;
  for (size_t i = 0; i < color.size(); ++i) {
    const std::string what = "colour point " + std::to_string(i + 1);
    const double x = number_in(color[i], "x", what);
    check_order(x, previous, what);
    if (!color[i].contains("rgb") || !color[i]["rgb"].is_string())
      throw std::invalid_argument(what + ": \"rgb\" must be #rrggbb");
    const std::string text = color[i]["rgb"].get<std::string>();
    Rgb srgb = parse_hex(text, what);
    const nlohmann::json* exact = color[i].contains("srgb") ? &color[i]["srgb"] : nullptr;
    if (exact && exact->is_array() && exact->size() == 3 && (*exact)[0].is_number() && (*exact)[1].is_number() &&
        (*exact)[2].is_number()) {
      const Rgb e{(*exact)[0].get<double>(), (*exact)[1].get<double>(), (*exact)[2].get<double>()};
      const bool in_unit = e[0] >= 0 && e[0] <= 1 && e[1] >= 0 && e[1] <= 1 && e[2] >= 0 && e[2] <= 1;
      std::string lower = text;
      std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
      if (in_unit && hex_color(e) == lower) srgb = e;
    }
    cp.color.push_back({x, srgb});
    previous = x;
  }
  return cp;
}

}  // namespace tfm
