// Transfer functions from and for other tools: the XML format of the paper's framework (sgl /
// Correrender: <TransferFunction colorspace=... interpolation_colorspace=...>), ParaView colour
// map presets (JSON "RGBPoints"/"Points") and tfmatch's own JSON table; control points are
// converted to the node-aligned table (DESIGN.md) and back.
//
// Colours: tfmatch tables hold linear RGB (tf_to_json writes "colorspace": "linear-rgb"). The
// XML format stores sRGB points (colorspace="sRGB") and blends them in sRGB or linear RGB; a
// ParaView preset's colours are display (sRGB) values blended in its ColorSpace. Reading
// converts the blended sRGB colour at each table node to linear RGB; writing converts each node
// back to sRGB. Opacity is copied as is (ParaView's midpoint/sharpness shape is honoured).
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "tfmatch/io/tf_json.h"
#include "tfmatch/model/builtin_tf.h"
#include "tfmatch/model/color_spaces.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

struct ControlPointTf {
  struct OpacityPoint {
    double position = 0, opacity = 0;
    double midpoint = 0.5, sharpness = 0.0;  // ParaView's shape of the segment to the next point
  };
  struct ColorPoint {
    double position = 0;
    Rgb srgb{0, 0, 0};
  };
  std::vector<OpacityPoint> opacity;  // positions in [0,1]
  std::vector<ColorPoint> color;
  ColorInterpolation interpolation = ColorInterpolation::SRgb;
  std::optional<FieldRange> range;
  // The table size the file states (a preset tfmatch wrote): its entries are among the points.
  std::optional<size_t> table_size;
};

// The table of `n` entries (n = 0: auto_table_size) at t = j/(n-1), RGB linear.
TransferFunction table_from_control_points(const ControlPointTf& cp, size_t n = 0);
// One control point per table entry (exact at the nodes; linear RGB between them).
ControlPointTf control_points_from_table(const TransferFunction& tf);
// 256 entries (the framework's own table size), refined so that every control point lies on a
// node when the points sit on a grid k/d with d <= 4096 (then the table is exact for linear-RGB
// blending): n - 1 = d * ceil(255 / d); points on a finer grid up to d = kMaxTableSize - 1 (a
// large table written by tfmatch) give n = d + 1; points on no grid give 4 entries a point, 256 to
// kMaxTableSize.
size_t auto_table_size(const ControlPointTf& cp);

// XML of the framework. Throws std::runtime_error "<name>: ..." for malformed XML, a missing
// <TransferFunction>, points without numbers, non-finite values or no points at all. Opacities
// and colours outside [0, 1] are clamped, as the framework does, with a line in `notes` saying
// how many.
ControlPointTf parse_tf_xml(std::string_view text, const std::string& name, std::vector<std::string>* notes = nullptr);
std::string tf_to_xml(const TransferFunction& tf);

// ParaView preset: an object, or an array of them (the one named `preset`, else the first).
// Positions are normalized by the span of all points; that span becomes the TF's data range
// unless it is exactly [0,1] (a normalized preset). Without "Points" the opacity is a ramp from
// 0 to 1, and a note says so.
ControlPointTf parse_paraview_preset(std::string_view text, const std::string& name, const std::string& preset = "",
                                     std::vector<std::string>* notes = nullptr);
std::string tf_to_paraview_json(const TransferFunction& tf, const std::string& preset_name);

struct TfReadOptions {
  size_t table_size = 0;   // entries of the table made from control points (0: auto_table_size)
  std::string preset;      // ParaView preset name in a file holding several
};

// The built-in map that `spec` names (builtin_tf.h), if it names one: a spec is a built-in name
// (optionally with ",opacity=SHAPE") only when no file of exactly that name exists, so a file
// called "viridis" is still read as a file. Throws std::runtime_error for a built-in name with a
// bad option ("viridis,opacity=round").
std::optional<BuiltinTf> builtin_tf_named_by(const std::string& spec);

// A built-in map's name (builtin_tf_named_by; a table of options.table_size entries, 64 when 0),
// else a file by content: XML (first non-blank character '<'), a JSON object with "rgba"
// (tfmatch), else a ParaView preset. `path` may end in ":PRESET" to name a preset. `notes`
// (optional) receives what the reader assumed (for a built-in: its source, size and opacity).
// Throws std::runtime_error naming the file; for a path that is neither a file nor a built-in
// name, the message lists the built-in names.
TransferFunction read_transfer_function(const std::filesystem::path& path, const TfReadOptions& options = {},
                                        std::vector<std::string>* notes = nullptr);
TransferFunction parse_transfer_function(std::string_view text, const std::string& name, const TfReadOptions& options = {},
                                         std::vector<std::string>* notes = nullptr);
// By extension: .xml (framework XML), *.paraview.json (ParaView preset), other .json (tfmatch
// table). Atomic.
void write_transfer_function(const std::filesystem::path& path, const TransferFunction& tf);

}  // namespace tfm
