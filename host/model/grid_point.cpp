// Grid points from text: indices or coordinates matched to the volume's axes.
#include "tfmatch/model/grid_point.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace tfm {
namespace {

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : s) {
    if (c == sep) out.push_back(cur), cur.clear();
    else if (c != ' ') cur.push_back(c);
  }
  out.push_back(cur);
  return out;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// Which axis a coordinate name refers to, or -1.
int axis_of_key(const Volume& grid, const std::string& key) {
  const std::string k = lower(key);
  for (int a = 0; a < 3; ++a)
    if (!grid.axes[a].name.empty() && lower(grid.axes[a].name) == k) return a;
  if (k == "x" || k == "lon" || k == "longitude") return 0;
  if (k == "y" || k == "lat" || k == "latitude") return 1;
  if (k == "z" || k == "level" || k == "lev" || k == "height" || k == "depth") return 2;
  return -1;
}

bool is_longitude(const GridAxis& a) {
  const std::string n = lower(a.name), u = lower(a.units);
  return n.starts_with("lon") || u == "degrees_east" || u == "degree_east";
}

}  // namespace

GridIndex parse_grid_index(const std::string& text, const std::string& what) {
  const auto parts = split(text, ',');
  GridIndex p{};
  bool ok = parts.size() == 3;
  for (size_t i = 0; ok && i < 3; ++i) {
    const std::string& t = parts[i];
    auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), p[i]);
    ok = !t.empty() && ec == std::errc() && end == t.data() + t.size();
  }
  if (!ok) throw std::invalid_argument(what + " '" + text + "': expected I,J,K (three non-negative grid indices)");
  return p;
}

GridIndex resolve_grid_point(const Volume& grid, const std::string& text, const std::string& what,
                             std::vector<std::string>* warnings) {
  std::ostringstream dims;
  dims << grid.dims[0] << "x" << grid.dims[1] << "x" << grid.dims[2];
  if (text.find('=') == std::string::npos) {
    const GridIndex p = parse_grid_index(text, what);
    for (int a = 0; a < 3; ++a)
      if (p[a] >= grid.dims[a])
        throw std::invalid_argument(what + " '" + text + "': index " + std::to_string(p[a]) + " along " + "xyz"[a] +
                                    " is outside the grid " + dims.str() + " of " + grid.name);
    return p;
  }
  std::array<bool, 3> given{false, false, false};
  GridIndex p{};
  for (const auto& item : split(text, ',')) {
    const auto eq = item.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument(what + " '" + text + "': expected NAME=VALUE items such as lon=10,lat=45,level=500");
    const std::string key = item.substr(0, eq), value_text = item.substr(eq + 1);
    const int a = axis_of_key(grid, key);
    if (a < 0)
      throw std::invalid_argument(what + " '" + text + "': '" + key + "' names no axis of " + grid.name +
                                  " (use lon, lat, level, x, y, z or the axis names " + grid.axes[0].name + ", " +
                                  grid.axes[1].name + ", " + grid.axes[2].name + ")");
    char* end = nullptr;
    const double value = std::strtod(value_text.c_str(), &end);
    if (value_text.empty() || *end != '\0' || !std::isfinite(value))
      throw std::invalid_argument(what + " '" + text + "': '" + value_text + "' is not a number");
    if (given[a]) throw std::invalid_argument(what + " '" + text + "': axis " + std::string(1, "xyz"[a]) + " given twice");
    given[a] = true;
    const GridAxis& axis = grid.axes[a];
    // Nearest coordinate (longitudes modulo 360); outside the axis by more than one step: error.
    double best = INFINITY;
    for (uint64_t i = 0; i < grid.dims[a]; ++i) {
      double d = std::abs(axis_coordinate(grid, a, i) - value);
      if (is_longitude(axis)) {
        const double m = std::fmod(d, 360.0);
        d = std::min(m, 360.0 - m);
      }
      if (d < best) best = d, p[a] = i;
    }
    const double lo = axis_coordinate(grid, a, 0), hi = axis_coordinate(grid, a, grid.dims[a] - 1);
    const double step = grid.dims[a] > 1 ? std::abs(hi - lo) / double(grid.dims[a] - 1) : 0.0;
    if (is_longitude(axis)) continue;
    const double tolerance = 1e-9 * std::max(std::abs(value), step);
    const bool outside = value < std::min(lo, hi) - tolerance || value > std::max(lo, hi) + tolerance;
    if (!outside) continue;
    std::ostringstream range;
    range << (axis.name.empty() ? std::string(1, "xyz"[a]) : axis.name) << " range " << std::min(lo, hi) << " .. "
          << std::max(lo, hi);
    if (best > step + tolerance)
      throw std::invalid_argument(what + " '" + text + "': " + key + "=" + value_text + " is outside " + grid.name +
                                  "'s " + range.str());
    // Within a step of an end: taken as that end, which is not what was asked, so said.
    if (warnings) {
      std::ostringstream w;
      w << what << " '" << text << "': " << key << "=" << value_text << " lies outside " << grid.name << "'s "
        << range.str() << "; the nearest, " << axis_coordinate(grid, a, p[a]) << ", is used";
      warnings->push_back(w.str());
    }
  }
  for (int a = 0; a < 3; ++a)
    if (!given[a] && grid.dims[a] > 1)
      throw std::invalid_argument(what + " '" + text + "': no coordinate for axis " + std::string(1, "xyz"[a]) +
                                  (grid.axes[a].name.empty() ? "" : " (" + grid.axes[a].name + ")") + ", which has " +
                                  std::to_string(grid.dims[a]) + " points");
  return p;
}

std::string describe_grid_point(const Volume& grid, const GridIndex& p) {
  std::ostringstream os;
  os << "(" << p[0] << ", " << p[1] << ", " << p[2] << ")";
  std::string coords;
  for (int a = 0; a < 3; ++a) {
    if (grid.axes[a].name.empty()) continue;
    std::ostringstream c;
    c << grid.axes[a].name << "=" << axis_coordinate(grid, a, p[a]);
    coords += (coords.empty() ? "" : ", ") + c.str();
  }
  if (!coords.empty()) os << " at " << coords;
  return os.str();
}

}  // namespace tfm
