// Points of a grid named on the command line: "I,J,K" (indices, I along x, the fastest axis) or
// "lon=..,lat=..,level=.." (coordinates, when the volume carries them), for correlation
// reference points and markers.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "tfmatch/model/volume.h"

namespace tfm {

using GridIndex = std::array<uint64_t, 3>;

// Parses "I,J,K" (non-negative integers) without a grid; throws std::invalid_argument naming
// `what` (e.g. "--marker") on anything else.
GridIndex parse_grid_index(const std::string& text, const std::string& what);

// "I,J,K" checked against the grid, or "NAME=VALUE,..." matched to the axes by coordinate: `lon`,
// `lat` and `level` (also `x`, `y`, `z`, or an axis's own name such as `lev` or `isobaricInhPa`)
// pick the nearest coordinate on that axis (the file's coordinates, else origin + i * spacing;
// longitudes compared modulo 360); an axis with one index may be left out. A coordinate beyond an
// end of its axis by at most one step is taken as that end, with a warning in `warnings` (level=1000
// on levels 500 and 850 is 850); further beyond, or anything else wrong, throws
// std::invalid_argument naming `what` and saying what is wrong.
GridIndex resolve_grid_point(const Volume& grid, const std::string& text, const std::string& what,
                             std::vector<std::string>* warnings = nullptr);

// "(I, J, K)" and, where the axes have names, "lon=.. lat=.. lev=..", for messages.
std::string describe_grid_point(const Volume& grid, const GridIndex& p);

// The voxel's linear index (x fastest).
inline uint64_t linear_index(const Volume& grid, const GridIndex& p) {
  return (p[2] * grid.dims[1] + p[1]) * grid.dims[0] + p[0];
}

}  // namespace tfm
