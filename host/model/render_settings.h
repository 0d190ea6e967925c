// The one set of rendering parameters (DESIGN.md) shared by the renderer, DiffDVR and the
// residual renderings, so the images optimized are the images shown.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace tfm {

// Orbit camera around the centre of the volume's bounding box (scaled by physical spacing).
// The grid's +z axis is "up": azimuth turns about it, elevation tilts towards it. Elevation
// +-90 looks straight down (up) the z axis; the image basis stays well defined there.
struct OrbitCamera {
  double azimuth_deg = 30.0;    // from +x towards +y
  double elevation_deg = 20.0;  // above the xy plane, in [-90, 90]
  // Eye to box centre, in bounding-sphere radii (> 1: outside). 0: framed, the nearest distance
  // at which all eight box corners fit in the image with a small margin, so a thin or elongated
  // box (a geophysical grid of 26 levels over 144 x 73 columns) is neither cut off nor tiny.
  double distance = 0.0;
  double fov_deg = 30.0;        // vertical field of view, in (0, 180)
};

struct RenderSettings {
  uint32_t width = 512;
  uint32_t height = 512;
  // Distance between samples along a ray, in voxels of the finest axis.
  double step_voxels = 0.5;
  // Extinction of a TF entry with opacity a is sigma = a * opacity_scale per box length (the
  // longest side of the bounding box): a step of dt box lengths has alpha = 1 - exp(-sigma dt).
  // Measuring in box lengths makes a setting look the same at any grid resolution.
  double opacity_scale = 20.0;
  std::array<double, 3> background{1.0, 1.0, 1.0};  // RGB in [0,1], composited when imaging
  // A ray stops once its opacity reaches this. Must be < 1: DiffDVR's backward pass inverts
  // compositing by dividing by the remaining transmittance (shaders/raymarch.glsl).
  double termination_opacity = 0.99;
  // Vertical exaggeration: the box's z extent is multiplied by this (geometry only; the field's
  // values and the opacity per box length are unchanged).
  double z_scale = 1.0;
  // Pictures for people get a thin outline of the box (drawn after compositing, so never part of
  // an image that is optimized or measured).
  bool box_outline = true;
  OrbitCamera camera;
};

// Throws std::runtime_error naming the first setting out of range.
inline void validate(const RenderSettings& s) {
  auto bad = [](const std::string& what) { throw std::runtime_error("render settings: " + what); };
  if (s.width == 0 || s.height == 0 || s.width > 16384 || s.height > 16384)
    bad("image size must be 1..16384 pixels per side");
  if (!(s.step_voxels >= 0.01 && s.step_voxels <= 64)) bad("step must be in [0.01, 64] voxels");
  if (!(s.opacity_scale >= 0 && std::isfinite(s.opacity_scale))) bad("opacity scale must be >= 0 and finite");
  for (double c : s.background)
    if (!(c >= 0 && c <= 1)) bad("background components must be in [0, 1]");
  if (!(s.termination_opacity > 0 && s.termination_opacity < 1))
    bad("termination opacity must be in (0, 1)");
  const OrbitCamera& c = s.camera;
  if (!std::isfinite(c.azimuth_deg)) bad("azimuth must be finite");
  if (!(c.elevation_deg >= -90 && c.elevation_deg <= 90)) bad("elevation must be in [-90, 90] degrees");
  if (!(c.distance == 0 || (c.distance > 1 && c.distance <= 1e4)))
    bad("distance must be 0 (framed) or in (1, 10000] bounding-sphere radii");
  if (!(s.z_scale >= 1e-3 && s.z_scale <= 1e4)) bad("z scale must be in [0.001, 10000]");
  if (!(c.fov_deg > 0 && c.fov_deg < 180)) bad("field of view must be in (0, 180) degrees");
}

}  // namespace tfm
