// The render flags every rendering subcommand shares (--azimuth, --elevation, --distance,
// --z-scale, --fov, --width, --height, --step, --opacity-scale, --background, --termination,
// --no-outline), defined once.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/image.h"
#include "tfmatch/model/render_defaults.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"

namespace tfm::cli {

// Adds the flags to `sub`, writing into `settings` (which must outlive parsing; its current
// values are the defaults shown in --help). Flags go into the group "Rendering".
void add_render_options(CLI::App* sub, RenderSettings& settings);
// --color-bar / --no-color-bar (group "Rendering"): a colour bar of the TF in a strip beneath the
// picture (color_bar.h). `on` holds the command's default, which the help states.
void add_color_bar_flag(CLI::App* sub, bool& on);
// The picture flags given on `sub`'s command line (after parsing): its "Rendering" group and the
// names in `also`, but those in `except`, each as typed (--no-color-bar, not --color-bar).
std::vector<std::string> given_picture_flags(const CLI::App& sub, std::initializer_list<const char*> also = {},
                                             std::initializer_list<const char*> except = {});
// The usage error for picture flags given where nothing is drawn, so that they would be dropped
// without a word: "--width, --step: shape the residual's picture: add --image FILE.png, or leave
// them out" (`picture`: "the residual's picture"; `fix`: "add --image FILE.png").
CLI::ValidationError unused_picture_flags(const std::vector<std::string>& flags, const std::string& picture,
                                          const std::string& fix);
// with_color_bar of `picture` with the render's background, or a note on stderr when the picture
// is too narrow for one (then `picture` stays as it is).
void add_picture_color_bar(Image& picture, const TransferFunction& tf, const FieldRange& range,
                           const std::string& title, const RenderSettings& settings);
// A note on stderr when `tf_spec` names a built-in diverging map laid over a range that neither
// the user (`range_given`) nor the TF gave and that is not centred on 0: where its neutral middle
// lies, and the `flag` value that centres it (diverging_middle_note).
void note_diverging_middle(const std::string& tf_spec, const TransferFunction& tf, bool range_given,
                           const FieldRange& range, const std::string& flag);
// Which of those flags the command line gave (after parsing `sub`): the grid's defaults
// (render_defaults.h, apply_grid_defaults) take the place of the others.
RenderChoices render_choices(const CLI::App& sub);

// --marker (repeatable): grid points drawn as red dots on the renderings (reference points of a
// correlation field), as I,J,K indices or lon=..,lat=..,level=.. coordinates.
void add_marker_option(CLI::App* sub, std::vector<std::string>& markers);
// --histogram log|linear: how the report's TF plots scale the histogram bars.
void add_histogram_option(CLI::App* sub, std::string& histogram);

// --slice-point: the voxel the report's slices go through (default: the grid's middle).
void add_slice_point_option(CLI::App* sub, std::string& point);

// resolve_grid_point (host/model/grid_point.h) with its warnings printed (a coordinate just past
// an axis's end, taken as the end).
GridIndex resolve_point(const Volume& grid, const std::string& text, const std::string& what);
// Resolves the --marker texts on `grid`; throws CLI::ValidationError saying what is wrong.
std::vector<GridIndex> resolve_markers(const Volume& grid, const std::vector<std::string>& texts);
// Resolves --slice-point (empty: none); throws CLI::ValidationError saying what is wrong.
std::optional<GridIndex> resolve_slice_point(const Volume& grid, const std::string& text);

// The range `v` is mapped to `tf` with: the flag's value (lo,hi) if given, else the TF file's,
// else the field's finite min/max. A range not from the field is checked against it
// (check_range_coverage): a warning goes to stderr, over 95 % outside is an error unless `allow`.
// `tf_spec`, the TF as given: a built-in diverging map on a range of the field's gets
// note_diverging_middle's note.
FieldRange field_range_for(const Volume& v, const TransferFunction& tf, const std::string& flag_value,
                           const std::string& flag, bool allow, const std::string& tf_spec = "");

// "white", "black", "gray", "#rrggbb" or "r,g,b" with components in [0,1], as written (the
// caller decides the colour space; --background reads it as sRGB). Throws
// CLI::ValidationError naming the flag.
std::array<double, 3> parse_color(const std::string& text, const std::string& flag);

}  // namespace tfm::cli
