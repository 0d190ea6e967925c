// Scalar volumes on regular grids (x fastest, then y, then z); files: host/io/volume_io.h.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tfm {

// What a file says about one grid axis beyond origin and spacing: its name, units and the
// coordinate of every index (NetCDF coordinate variables, GRIB latitudes/longitudes/levels).
struct GridAxis {
  std::string name;                 // "lon", "lat", "lev", "isobaricInhPa", ...; empty: unnamed
  std::string units;                // "degrees_east", "hPa", ...
  std::vector<double> coordinates;  // one per index; empty: origin + i * spacing
};

struct Volume {
  std::array<uint64_t, 3> dims{0, 0, 0};          // x, y, z
  std::array<double, 3> spacing{1.0, 1.0, 1.0};   // physical size of a voxel step
  std::array<double, 3> origin{0.0, 0.0, 0.0};    // physical position of voxel (0, 0, 0)
  std::array<GridAxis, 3> axes;                   // names, units, coordinates where the file has them
  std::vector<float> values;                      // NaN = no data
  std::string name;                               // where it came from, for messages
  std::string units;                              // the values' units where the file says ("K"), else ""

  uint64_t voxel_count() const { return dims[0] * dims[1] * dims[2]; }
  float at(uint64_t x, uint64_t y, uint64_t z) const { return values[(z * dims[1] + y) * dims[0] + x]; }
};

// The coordinate of index i along axis a: the file's coordinate when it has one, else
// origin + i * spacing.
double axis_coordinate(const Volume& v, int axis, uint64_t i);

// A volume with the grid (dims, spacing, origin, axes) and name of `like`, no values, no units.
Volume empty_like(const Volume& like);

// Throws std::runtime_error when the two volumes are not on one grid.
void require_same_grid(const Volume& a, const Volume& b);

// For two volumes with the same dims: "" when their spacing and origin agree (to 1e-6 of the
// spacing and of the grid's extent), else a warning naming both and the difference. Voxels are
// compared index by index whatever the geometry, and outputs take `a`'s, so a copy of a field
// written with another spacing (or the wrong file of a similar grid) is said, not refused.
std::string grid_geometry_warning(const Volume& a, const Volume& b);

}  // namespace tfm
