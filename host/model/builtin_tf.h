// Built-in transfer functions: well-known colour maps by name (`--ref-tf viridis`,
// `--tf diverging,opacity=flat`, `convert-tf cool-warm out.json`), each with an opacity shape,
// as node-aligned tables in tfmatch's linear-RGB convention (DESIGN.md).
//
// Maps (sources in colormap_tables.cpp), with their default opacity:
//   viridis, inferno   matplotlib's (van der Walt & Smith)        ramp
//   cool-warm          Moreland's diverging map (2009)             vee
//   grey               black to white                              ramp
//   diverging          ColorBrewer RdBu, blue (low) to red (high)  vee
// Opacity shapes of t in [0,1]: ramp = t; flat = 0.5 (the ramp's mean); tent = 1 - |2t - 1|
// (0 at the ends, 1 in the middle); vee = |2t - 1| (1 at the ends, 0 in the middle: for signed
// fields whose range is centred on zero, such as correlations, values near 0 are transparent
// and strong values of either sign opaque).
//
// Colours: the published sRGB points are joined by straight lines in sRGB, as matplotlib and
// ColorBrewer users see them, then each table entry is converted to linear RGB.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

enum class OpacityShape { Ramp, Flat, Tent, Vee };

struct BuiltinTf {
  std::string name;  // one of builtin_tf_names()
  OpacityShape opacity = OpacityShape::Ramp;
};

inline constexpr size_t kDefaultBuiltinTfSize = 64;
inline constexpr double kFlatOpacity = 0.5;

// The names, in the order messages list them.
const std::vector<std::string>& builtin_tf_names();
// "viridis, inferno, cool-warm, grey or diverging, optionally NAME,opacity=ramp|flat|tent|vee":
// what messages and --help say a built-in map is written as.
std::string builtin_tf_syntax();
// "ramp", "flat", "tent", "vee".
const char* opacity_shape_name(OpacityShape shape);
// The opacity of `shape` at t (clamped to [0,1]).
double opacity_at(OpacityShape shape, double t);
// The shape a map gets without ",opacity=". Throws std::invalid_argument for an unknown name.
OpacityShape default_opacity_shape(const std::string& name);
// Where the map's colours come from, for notes ("matplotlib's viridis (van der Walt & Smith)").
std::string builtin_tf_source(const std::string& name);

// Parses "NAME" or "NAME,opacity=SHAPE" (case-insensitive). Returns nullopt when NAME is not a
// built-in map (so the text may be a file name); throws std::invalid_argument naming the problem
// when NAME is one but what follows it is not an opacity option.
std::optional<BuiltinTf> parse_builtin_tf(std::string_view text);
// The map as `n` entries (n >= 2, else std::invalid_argument), without a range (the field's
// range applies).
TransferFunction builtin_transfer_function(const BuiltinTf& tf, size_t n = kDefaultBuiltinTfSize);

// The map `tfmatch view` starts from without a reference TF: "diverging" (vee) for a range with
// lo < 0 < hi, else "viridis" (ramp).
BuiltinTf default_builtin_tf(const FieldRange& range);

// Whether the map's colours diverge from a neutral middle (diverging, cool-warm: white or grey
// at t = 0.5), which a reader takes for zero.
bool diverging_builtin_tf(const std::string& name);
// For such a map laid over `range` (a field's min..max, not centred on zero): a note that its
// neutral middle lies at (lo + hi) / 2 rather than at 0, and that `range_flag` -m,m (m the larger
// of -lo and hi) puts it there. Empty for other maps, for ranges that do not span zero, and for
// ranges centred on zero within 0.1 % of their width.
std::string diverging_middle_note(const BuiltinTf& tf, const FieldRange& range, const std::string& range_flag);

}  // namespace tfm
