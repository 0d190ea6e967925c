// Grid checks of volumes.
#include "tfmatch/model/volume.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace tfm {

double axis_coordinate(const Volume& v, int axis, uint64_t i) {
  const auto& c = v.axes[axis].coordinates;
  if (i < c.size()) return c[i];
  return v.origin[axis] + double(i) * v.spacing[axis];
}

Volume empty_like(const Volume& like) {
  Volume v;
  v.dims = like.dims;
  v.spacing = like.spacing;
  v.origin = like.origin;
  v.axes = like.axes;
  v.name = like.name;  // not the units: the new values are another quantity (a residual, a correlation)
  return v;
}

void require_same_grid(const Volume& a, const Volume& b) {
  if (a.dims != b.dims) {
    std::ostringstream os;
    os << "fields are on different grids: " << a.name << " is " << a.dims[0] << "x" << a.dims[1] << "x"
       << a.dims[2] << ", " << b.name << " is " << b.dims[0] << "x" << b.dims[1] << "x" << b.dims[2];
    // The likely slip with a file of many variables: a 2-D one (a surface field) beside 3-D ones.
    const bool same_plane = a.dims[0] == b.dims[0] && a.dims[1] == b.dims[1];
    if (same_plane && (a.dims[2] == 1) != (b.dims[2] == 1))
      os << " (" << (a.dims[2] == 1 ? a.name : b.name) << " has one level: a 2-D field on the other's horizontal grid"
         << " of " << std::max(a.dims[2], b.dims[2]) << " levels)";
    throw std::runtime_error(os.str());
  }
}

std::string grid_geometry_warning(const Volume& a, const Volume& b) {
  // Relative to the grid's extent, so that a coordinate's rounding in a file is no difference.
  auto differs = [](const std::array<double, 3>& p, const std::array<double, 3>& q, const std::array<double, 3>& scale) {
    for (int i = 0; i < 3; ++i)
      if (std::abs(p[i] - q[i]) > 1e-6 * std::max({std::abs(p[i]), std::abs(q[i]), std::abs(scale[i])})) return true;
    return false;
  };
  std::array<double, 3> extent;
  for (int i = 0; i < 3; ++i) extent[i] = std::max(std::abs(a.spacing[i]), std::abs(b.spacing[i])) * double(a.dims[i]);
  const bool spacing = differs(a.spacing, b.spacing, a.spacing), origin = differs(a.origin, b.origin, extent);
  if (!spacing && !origin) return "";
  auto triple = [](const std::array<double, 3>& t) {
    std::ostringstream os;
    os << t[0] << " " << t[1] << " " << t[2];
    return os.str();
  };
  std::ostringstream os;
  os << a.name << " and " << b.name << " have the same " << a.dims[0] << "x" << a.dims[1] << "x" << a.dims[2]
     << " voxels but not the same geometry (";
  if (spacing) os << "spacing " << triple(a.spacing) << " against " << triple(b.spacing);
  if (spacing && origin) os << "; ";
  if (origin) os << "origin " << triple(a.origin) << " against " << triple(b.origin);
  os << "): voxels are compared index by index, and what is written takes " << a.name << "'s";
  return os.str();
}

}  // namespace tfm
