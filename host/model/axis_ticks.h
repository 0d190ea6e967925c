// Round values along an axis, and the labels and places of a grid's own coordinates (longitudes,
// latitudes, levels): what plots and renderings put on their axes.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "tfmatch/model/volume.h"

namespace tfm {

// `v` as an axis label: printf's %g with `significant` digits ("0.25", "1.5e+04").
std::string tick_label(double v, int significant = 4);

// About `target` round values (1, 2 or 5 times a power of ten apart) within [lo, hi].
std::vector<double> nice_ticks(double lo, double hi, int target = 5);

// Ticks for `axis` between lo and hi, about `target` of them: for longitudes and latitudes at the
// steps maps use (1, 2, 5, 10, 15, 20, 30, 45, 60, 90 degrees), else nice_ticks.
std::vector<double> axis_ticks(const GridAxis& axis, double lo, double hi, int target);

// Whether the axis is a longitude or a latitude (CF units degrees_east / degrees_north, or the
// names lon / longitude, lat / latitude).
bool is_longitude(const GridAxis& axis);
bool is_latitude(const GridAxis& axis);

// `value` as a label on `axis`: longitudes "10E", "170W", "0", "180" (wrapped into -180..180);
// latitudes "45N", "30S", "EQ"; other axes the number ("850"). ASCII, for the 5x7 font.
std::string coordinate_label(const GridAxis& axis, double value);

// Where `value` lies among the axis's coordinates, as a fractional index (coordinates at integer
// indices, linear between them; increasing or decreasing); nothing when outside them or when the
// axis has no strictly monotone coordinates.
std::optional<double> coordinate_index(const GridAxis& axis, double value);

}  // namespace tfm
