// Which axes of a geographic grid to reverse so that x points east, y north and z up, and the
// reversal itself (see grid_orientation.h).
#include "tfmatch/io/grid_orientation.h"

#include <algorithm>
#include <cmath>
#include <cctype>
#include <sstream>

namespace tfm {
namespace {

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool contains(const std::string& s, const char* part) { return s.find(part) != std::string::npos; }

// +1 strictly increasing, -1 strictly decreasing, 0 neither (or too short to tell).
int monotone(const std::vector<double>& c) {
  if (c.size() < 2) return 0;
  bool up = true, down = true;
  for (size_t i = 1; i < c.size(); ++i) {
    up &= c[i] > c[i - 1];
    down &= c[i] < c[i - 1];
  }
  return up ? 1 : down ? -1 : 0;
}

const char* direction_word(AxisKind k) {
  switch (k) {
    case AxisKind::Longitude: return "east";
    case AxisKind::Latitude: return "north";
    case AxisKind::Pressure: return "up (pressure decreasing, surface at z = 0)";
    case AxisKind::Height: return "up (height increasing)";
    case AxisKind::Depth: return "up (depth decreasing, deepest at z = 0)";
    case AxisKind::Other: break;
  }
  return "file order";
}

}  // namespace

AxisKind classify_axis(int axis, const GridAxis& a, const std::string& cf_positive) {
  const std::string name = lower(a.name), units = lower(a.units), positive = lower(cf_positive);
  if (axis == 0)
    return contains(units, "east") || units == "degrees_e" || name.rfind("lon", 0) == 0 ? AxisKind::Longitude
                                                                                      : AxisKind::Other;
  if (axis == 1)
    return contains(units, "north") || units == "degrees_n" || name.rfind("lat", 0) == 0 ? AxisKind::Latitude
                                                                                        : AxisKind::Other;
  if (axis != 2) return AxisKind::Other;
  static const char* pressure_units[] = {"pa", "hpa", "kpa", "mbar", "millibar", "millibars", "mb", "bar", "atm"};
  const bool pressure_unit = std::any_of(std::begin(pressure_units), std::end(pressure_units),
                                         [&](const char* u) { return units == u; });
  // Hybrid model levels are numbered from the top down, like pressure.
  if (pressure_unit || contains(name, "isobaric") || contains(name, "pressure") || name == "plev" || name == "hybrid")
    return AxisKind::Pressure;
  if (contains(name, "depth") || positive == "down") return AxisKind::Depth;
  if (contains(name, "height") || contains(name, "altitude") || positive == "up") return AxisKind::Height;
  return AxisKind::Other;
}

WorldOrientation world_orientation(const std::array<GridAxis, 3>& axes, const std::array<uint64_t, 3>& dims,
                                   const std::array<std::string, 3>& cf_positive) {
  WorldOrientation o;
  for (int k = 0; k < 3; ++k) {
    o.kind[k] = classify_axis(k, axes[k], cf_positive[k]);
    if (o.kind[k] == AxisKind::Other || axes[k].coordinates.size() != dims[k]) continue;
    const int m = monotone(axes[k].coordinates);
    const bool should_decrease = o.kind[k] == AxisKind::Pressure || o.kind[k] == AxisKind::Depth;
    o.flip[k] = should_decrease ? m > 0 : m < 0;
  }
  return o;
}

void apply_world_orientation(Volume& v, const WorldOrientation& o) {
  const uint64_t nx = v.dims[0], ny = v.dims[1], nz = v.dims[2];
  if (o.flip[0] || o.flip[1] || o.flip[2]) {
    std::vector<float> out(v.values.size());
    for (uint64_t z = 0; z < nz; ++z)
      for (uint64_t y = 0; y < ny; ++y)
        for (uint64_t x = 0; x < nx; ++x) {
          const uint64_t sx = o.flip[0] ? nx - 1 - x : x, sy = o.flip[1] ? ny - 1 - y : y, sz = o.flip[2] ? nz - 1 - z : z;
          out[(z * ny + y) * nx + x] = v.values[(sz * ny + sy) * nx + sx];
        }
    v.values = std::move(out);
  }
  orient_axes(v.axes, v.origin, v.spacing, o);
}

void orient_axes(std::array<GridAxis, 3>& axes, std::array<double, 3>& origin, const std::array<double, 3>& spacing,
                 const WorldOrientation& o) {
  for (int k = 0; k < 3; ++k) {
    auto& c = axes[k].coordinates;
    if (o.flip[k]) std::reverse(c.begin(), c.end());
    if (c.empty()) continue;
    // Whether origin c[0] and the spacing put every coordinate within half a step of its own
    // (a nearly regular axis, such as Gaussian latitudes with their mean step, keeps its origin).
    const double tolerance = 0.5 * std::abs(spacing[size_t(k)]);
    bool affine = true;
    for (size_t i = 0; i < c.size() && affine; ++i)
      affine = std::abs(c.front() + double(i) * spacing[size_t(k)] - c[i]) <= tolerance;
    origin[k] = affine ? c.front() : 0.0;
  }
}

std::vector<std::string> orientation_lines(const std::array<GridAxis, 3>& axes, const std::array<double, 3>& origin,
                                           const std::array<double, 3>& spacing, const WorldOrientation& o) {
  std::vector<std::string> lines;
  for (int k = 0; k < 3; ++k) {
    const GridAxis& a = axes[k];
    std::ostringstream os;
    os.precision(7);
    os << "xyz"[k];
    if (!a.name.empty()) os << " (" << a.name << ")";
    os << ": ";
    if (!a.coordinates.empty()) os << a.coordinates.front() << " .. " << a.coordinates.back();
    else os << "origin " << origin[k] << ", spacing " << spacing[k];
    if (!a.units.empty()) os << " " << a.units;
    os << ", " << direction_word(o.kind[k]);
    if (o.flip[k]) os << ", reversed from the file's order";
    lines.push_back(os.str());
  }
  return lines;
}

}  // namespace tfm
