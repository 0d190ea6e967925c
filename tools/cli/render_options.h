// The render flags every rendering subcommand shares (--azimuth, --elevation, --distance,
// --fov, --width, --height, --step, --opacity-scale, --background, --termination), defined once.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "grid_point.h"
#include "render_settings.h"
#include "volume.h"
#include "volume_io.h"

namespace tfm::cli {

// Adds the flags to `sub`, writing into `settings` (which must outlive parsing; its current
// values are the defaults shown in --help). Flags go into the group "Rendering".
void add_render_options(CLI::App* sub, RenderSettings& settings);

// Raw-file flags of the rendering commands (--dims, --type, --big-endian), as `optimize` has them.
struct VolumeFlags {
  std::vector<uint64_t> dims;
  std::string type;
  bool big_endian = false;
  // Throws std::runtime_error for an unknown --type.
  VolumeOptions options() const;
};
void add_volume_flags(CLI::App* sub, VolumeFlags& flags);

// --marker (repeatable): grid points drawn as red dots on the renderings (reference points of a
// correlation field), as I,J,K indices or lon=..,lat=..,level=.. coordinates.
void add_marker_option(CLI::App* sub, std::vector<std::string>& markers);
// Resolves the --marker texts on `grid`; throws CLI::ValidationError saying what is wrong.
std::vector<GridIndex> resolve_markers(const Volume& grid, const std::vector<std::string>& texts);

// "white", "black", "gray", "#rrggbb" or "r,g,b" with components in [0,1]. Throws
// CLI::ValidationError naming the flag.
std::array<double, 3> parse_color(const std::string& text, const std::string& flag);

}  // namespace tfm::cli
