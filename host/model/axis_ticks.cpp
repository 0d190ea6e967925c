// Axis ticks and coordinate labels.
#include "tfmatch/model/axis_ticks.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace tfm {
namespace {

// The multiples of `step` within [lo, hi].
std::vector<double> multiples(double lo, double hi, double step) {
  std::vector<double> ticks;
  for (double k = std::ceil(lo / step - 1e-9); k * step <= hi + 1e-9 * step; k += 1)
    ticks.push_back(std::abs(k) < 1e-12 ? 0.0 : k * step);  // no "-0"
  return ticks;
}

}  // namespace

std::string tick_label(double v, int significant) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*g", significant, v);
  return buf;
}

std::vector<double> nice_ticks(double lo, double hi, int target) {
  if (!(hi > lo) || !std::isfinite(lo) || !std::isfinite(hi) || target < 1) return {};
  const double raw = (hi - lo) / target, mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double step = raw / mag < 1.5 ? mag : raw / mag < 3.5 ? 2 * mag : raw / mag < 7.5 ? 5 * mag : 10 * mag;
  return multiples(lo, hi, step);
}

std::vector<double> axis_ticks(const GridAxis& axis, double lo, double hi, int target) {
  const double raw = target >= 1 ? (hi - lo) / target : 0.0;
  // Other axes, and degrees finer than one (decimal steps), as nice_ticks has them.
  if (!(is_longitude(axis) || is_latitude(axis)) || !std::isfinite(lo) || !std::isfinite(hi) || !(raw >= 0.75))
    return nice_ticks(lo, hi, target);
  double step = 90.0;
  for (double s : {1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 45.0, 60.0, 90.0})
    if (s >= raw * 0.75) {
      step = s;
      break;
    }
  return multiples(lo, hi, step);
}

bool is_longitude(const GridAxis& a) {
  return a.units == "degrees_east" || a.units == "degree_east" || a.name == "lon" || a.name == "longitude";
}

bool is_latitude(const GridAxis& a) {
  return a.units == "degrees_north" || a.units == "degree_north" || a.name == "lat" || a.name == "latitude";
}

std::string coordinate_label(const GridAxis& axis, double value) {
  if (is_longitude(axis)) {
    double lon = std::fmod(value, 360.0);
    if (lon > 180.0) lon -= 360.0;
    if (lon <= -180.0) lon += 360.0;
    if (std::abs(lon) < 1e-9) return "0";
    if (std::abs(std::abs(lon) - 180.0) < 1e-9) return "180";
    return tick_label(std::abs(lon)) + (lon > 0 ? "E" : "W");
  }
  if (is_latitude(axis)) {
    if (std::abs(value) < 1e-9) return "EQ";
    return tick_label(std::abs(value)) + (value > 0 ? "N" : "S");
  }
  return tick_label(std::abs(value) < 1e-9 ? 0.0 : value);  // no "-0" or "1e-15" for a level at 0
}

std::optional<double> coordinate_index(const GridAxis& axis, double value) {
  const std::vector<double>& c = axis.coordinates;
  if (c.size() < 2 || !std::isfinite(value)) return std::nullopt;
  const bool up = c.back() > c.front();
  for (size_t i = 0; i + 1 < c.size(); ++i)
    if (!(up ? c[i + 1] > c[i] : c[i + 1] < c[i])) return std::nullopt;  // not strictly monotone
  for (size_t i = 0; i + 1 < c.size(); ++i) {
    const double a = c[i], b = c[i + 1];
    const double lo = std::min(a, b), hi = std::max(a, b);
    if (value >= lo - 1e-9 * (hi - lo) && value <= hi + 1e-9 * (hi - lo))
      return double(i) + std::clamp((value - a) / (b - a), 0.0, 1.0);
  }
  return std::nullopt;
}

}  // namespace tfm
