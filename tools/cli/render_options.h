// The render flags every rendering subcommand shares (--azimuth, --elevation, --distance,
// --fov, --width, --height, --step, --opacity-scale, --background, --termination), defined once.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

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

// "white", "black", "gray", "#rrggbb" or "r,g,b" with components in [0,1]. Throws
// CLI::ValidationError naming the flag.
std::array<double, 3> parse_color(const std::string& text, const std::string& flag);

}  // namespace tfm::cli
