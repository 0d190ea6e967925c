// World orientation of geographic grids (DESIGN.md "Colour, orientation, geometry"): x east,
// y north, z up. The NetCDF and GRIB loaders reverse the axes whose coordinates run the other
// way (latitudes stored north to south, pressure levels stored from the top), data and
// coordinates together, so every picture is north-up and surface-down; other grids keep the
// file's index order.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "tfmatch/model/volume.h"

namespace tfm {

// What an axis measures, from its name, units and (NetCDF) CF "positive" attribute.
enum class AxisKind { Other, Longitude, Latitude, Pressure, Height, Depth };

// Only the kinds that belong at the axis's place count: longitude on x, latitude on y, the
// vertical kinds on z; anything else is Other.
AxisKind classify_axis(int axis, const GridAxis& a, const std::string& cf_positive = "");

struct WorldOrientation {
  std::array<AxisKind, 3> kind{AxisKind::Other, AxisKind::Other, AxisKind::Other};
  std::array<bool, 3> flip{false, false, false};  // reversed from the file's index order
};

// The kinds of the three axes and which of them to reverse: longitude, latitude and height must
// increase with the index, pressure and depth decrease (the surface at z = 0). An axis without
// one coordinate per index, or whose coordinates are not strictly monotone, is never reversed.
WorldOrientation world_orientation(const std::array<GridAxis, 3>& axes, const std::array<uint64_t, 3>& dims,
                                   const std::array<std::string, 3>& cf_positive = {});

// Reverses the coordinates of the axes `o` flips. An axis with coordinates gets its first one as
// origin where origin + i * spacing puts each within half a step of its own (an even or nearly
// even axis in the spacing's units: longitudes, Gaussian latitudes, metres), else origin 0: an
// uneven or descending axis (pressure levels 850, 500 hPa) is in index units, its coordinates in
// the axes alone, so that a file written with that origin and spacing does not put 500 hPa at
// 851. No data: what `info` shows.
void orient_axes(std::array<GridAxis, 3>& axes, std::array<double, 3>& origin, const std::array<double, 3>& spacing,
                 const WorldOrientation& o);

// Reverses the data of the axes `o` flips, then orient_axes (dims and spacing unchanged).
void apply_world_orientation(Volume& v, const WorldOrientation& o);

// "x (longitude): 0 .. 357.5 degrees_east, east" and so on, one line per axis, for `info`
// (axes as oriented).
std::vector<std::string> orientation_lines(const std::array<GridAxis, 3>& axes, const std::array<double, 3>& origin,
                                           const std::array<double, 3>& spacing, const WorldOrientation& o);

}  // namespace tfm
