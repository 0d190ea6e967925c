// Grid checks of volumes.
#include "tfmatch/model/volume.h"

#include <algorithm>
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
  v.name = like.name;
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

}  // namespace tfm
