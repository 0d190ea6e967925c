// The grid-dependent defaults of every picture (`tfmatch render`, reports, the viewer): a thin grid
// (a few pressure levels over a map) is seen from above, north up, with its opacity scaled so the
// slab accumulates colour; RenderSettings' own defaults suit boxes of any other shape.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "tfmatch/model/render_settings.h"

namespace tfm {

// Which settings the user chose; those keep the user's values.
struct RenderChoices {
  bool camera_angles = false;  // azimuth or elevation
  bool opacity_scale = false;
  bool image_size = false;  // width or height
};

// True for at most 4 levels, or a box (physical spacing, z scale applied) whose height is at
// most 1/8 of its shorter horizontal side.
bool is_thin_grid(const std::array<uint64_t, 3>& dims, const std::array<double, 3>& spacing, double z_scale);

// For a thin grid, what the user did not choose: the camera looks straight down with north up and
// east to the right (azimuth -90, elevation 90); opacity_scale is multiplied by the box length over
// its height, so a ray down through the slab meets the optical depth a ray through a cube meets
// with the plain default (opacity is per box length: through two levels of a 120 x 61 grid a
// default ray reached about 1/180 of it, and the picture stayed white); looking down, the image
// takes the map's aspect (its longer side the larger of width and height). Other grids are left as they are.
// Returns what it set, for a note ("a thin grid (120x61x2): seen from above, north up; opacity scale
// 20 x box length / height 180 = 3600 (...)"), or "" when it set nothing. A scale the user gives is
// used as it is: the factor is printed so that it can be given scaled.
std::string apply_grid_defaults(RenderSettings& s, const std::array<uint64_t, 3>& dims,
                                const std::array<double, 3>& spacing, const RenderChoices& chosen);

}  // namespace tfm
