// The reference-TF editor's control points (`tfmatch view`): a table shown as the few points a
// person can drag, and the points a page sends back turned into a table again.
#pragma once

#include <cstddef>
#include <string>

#include "tfmatch/io/json.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

// Control points of `tf` for editing, blended in linear RGB (as tfmatch tables are): every entry
// when the table has at most `all_up_to` entries; else, separately for opacity and colour, the
// fewest entries (the first and last always among them, each added where the curve through the
// points chosen so far is furthest from the table) whose piecewise-linear curve stays within
// `tolerance` of every entry (opacity, and each linear RGB channel), at most `max_points`.
ControlPointTf editor_points(const TransferFunction& tf, size_t all_up_to = 16, double tolerance = 1.0 / 255.0,
                             size_t max_points = 48);

// {"opacity": [{"x", "a"}...], "color": [{"x", "rgb": "#rrggbb", "srgb": [r, g, b]}...]}.
nlohmann::json editor_points_json(const ControlPointTf& cp);

// The points of such a JSON object. A colour's "srgb" numbers are used when they round to its
// "rgb" text (an untouched point keeps its exact colour), else the text. Throws
// std::invalid_argument naming the first problem: not 2..256 points of each kind, x outside
// [0, 1] or not ascending, opacity outside [0, 1], a colour that is not #rrggbb.
ControlPointTf parse_editor_points(const nlohmann::json& doc);

// "#rrggbb" of an sRGB colour with components in [0, 1] (rounded, clamped).
std::string hex_color(const Rgb& srgb);

}  // namespace tfm
