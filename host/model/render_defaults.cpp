// Grid-dependent picture defaults (render_defaults.h).
#include "tfmatch/model/render_defaults.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "tfmatch/model/camera.h"

namespace tfm {

bool is_thin_grid(const std::array<uint64_t, 3>& dims, const std::array<double, 3>& spacing, double z_scale) {
  if (dims[2] <= 4) return true;
  const glm::dvec3 h = VolumeGeometry::from(dims, spacing, z_scale).half_extent();
  return h.z * 8.0 <= std::min(h.x, h.y);
}

std::string apply_grid_defaults(RenderSettings& s, const std::array<uint64_t, 3>& dims,
                                const std::array<double, 3>& spacing, const RenderChoices& chosen) {
  if (!is_thin_grid(dims, spacing, s.z_scale)) return "";
  const VolumeGeometry g = VolumeGeometry::from(dims, spacing, s.z_scale);
  const glm::dvec3 h = g.half_extent();
  std::ostringstream note;
  note << "a thin grid (" << dims[0] << "x" << dims[1] << "x" << dims[2] << "):";
  bool changed = false;
  if (!chosen.camera_angles) {
    s.camera.azimuth_deg = -90.0;
    s.camera.elevation_deg = 90.0;
    note << " seen from above, north up;";
    changed = true;
  }
  if (!chosen.opacity_scale) {
    const double factor = g.box_length() / (2.0 * h.z);
    note << " opacity scale " << s.opacity_scale << " x box length / height " << factor << " = "
         << s.opacity_scale * factor << " (--opacity-scale sets the scale itself);";
    s.opacity_scale *= factor;
    changed = true;
  }
  if (!chosen.image_size && !chosen.camera_angles) {
    // Framed from above, the box's x and y sides fill the picture's width and height alike.
    const double aspect = std::clamp(h.y / h.x, 0.25, 4.0);
    const double side = std::max(s.width, s.height);
    s.width = uint32_t(std::lround(aspect <= 1 ? side : side / aspect));
    s.height = uint32_t(std::lround(aspect <= 1 ? side * aspect : side));
    note << " " << s.width << "x" << s.height << " pixels, the map's aspect;";
  }
  if (!changed) return "";
  std::string text = note.str();
  text.pop_back();  // the last ';'
  return text;
}

}  // namespace tfm
