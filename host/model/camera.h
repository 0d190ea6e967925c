// Volume box geometry, the orbit camera's frame and per-ray setup in double precision: the CPU
// mirror of setup_ray() in shaders/raymarch.glsl, and what the GPU wrappers pack into floats.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include <glm/glm.hpp>

#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/grid_point.h"
#include "tfmatch/model/image.h"
#include "tfmatch/model/render_settings.h"
#include "tfmatch/model/volume.h"

namespace tfm {

// World space is voxel index space scaled per axis by spacing / finest spacing, so one world unit
// is one voxel of the finest axis. Voxel centres sit at integer index coordinates; the box the
// rays march through is [-0.5, n - 0.5] per axis (clamp-to-edge sampling near the faces).
struct VolumeGeometry {
  std::array<uint64_t, 3> dims{1, 1, 1};
  glm::dvec3 axis_scale{1.0};  // world = index * axis_scale

  // Throws std::runtime_error for an empty grid or non-positive / non-finite spacing. `z_scale`
  // stretches z (RenderSettings::z_scale, vertical exaggeration).
  static VolumeGeometry from(const std::array<uint64_t, 3>& dims, const std::array<double, 3>& spacing,
                             double z_scale = 1.0);
  glm::dvec3 center() const;       // world
  glm::dvec3 half_extent() const;  // world
  double radius() const;           // of the bounding sphere, world
  double box_length() const;       // longest side, world (the unit of opacity_scale)
};

struct CameraFrame {
  glm::dvec3 eye, forward, right, up;  // world; forward, right, up orthonormal, right = forward x up
  double tan_half_fov = 0.0;
  double aspect = 1.0;
};

// The orbit camera's frame. The basis is written in closed form (right = azimuth tangent,
// up = elevation tangent), so it is continuous and orthonormal at every elevation, the poles
// included, where a cross product with a fixed up vector would vanish. Distance 0 frames the
// box: the eye backs off along the view direction until every corner projects inside 94 % of
// the image's half-width and half-height.
CameraFrame orbit_frame(const OrbitCamera& camera, const VolumeGeometry& geometry, uint32_t width, uint32_t height);

// Optical depth of one sample is clamped to this so its transmittance exp(-depth) stays a normal
// float for DiffDVR's division (TFM_MAX_SAMPLE_OPTICAL_DEPTH of shaders/render_layout.h).
inline constexpr double kMaxSampleOpticalDepth = 20.0;

// Per-dispatch marching constants, derived once from the settings and the geometry.
struct MarchConstants {
  double dt = 0.5;               // world units
  double depth_per_alpha = 0.0;  // optical depth of one step at TF opacity 1
  double stop_transmittance = 0.01;
  uint32_t max_steps = 0;        // box diagonal / dt + 2: bounds every ray's sample count
};
// Validates the settings (throws std::runtime_error) and derives the constants.
MarchConstants march_constants(const RenderSettings& settings, const VolumeGeometry& geometry);

// A ray in index space: sample k at entry + (k + 0.5) dt dir, k < steps. Its samples share the
// chord's optical length: a sample's optical depth is depth_scale = (t_exit - t_entry) / (steps dt)
// times MarchConstants::depth_per_alpha (a ray cut at max_steps keeps dt: depth_scale 1).
struct RaySegment {
  glm::dvec3 entry{0.0}, dir{0.0};
  double t_entry = 0.0, t_exit = 0.0;  // world distances from the eye
  uint32_t steps = 0;
  double depth_scale = 1.0;
  // True when (t_exit - t_entry) / dt lies within `tolerance` of a half-integer, where float
  // and double may round the sample count differently (tests treat such pixels separately).
  bool steps_ambiguous = false;
};

RaySegment pixel_ray(const CameraFrame& frame, const VolumeGeometry& geometry, const MarchConstants& march,
                     uint32_t px, uint32_t py, uint32_t width, uint32_t height, double tolerance = 1e-4);

// Where a point given in index space (voxel centres at integers) appears in the image: pixel
// coordinates whose integer + 0.5 is a pixel centre (the inverse of pixel_ray's mapping), or
// nothing when the point is behind the eye.
std::optional<glm::dvec2> project_to_pixel(const CameraFrame& frame, const VolumeGeometry& geometry,
                                           const glm::dvec3& index_point, uint32_t width, uint32_t height);

// The twelve edges of the box rays march through ([-0.5, n - 0.5] per axis), projected and drawn
// as thin lines: where the data ends, and which way is up, even where the TF is clear. The three
// from voxel (0, 0, 0)'s corner are the axes: red x, green y, blue z, named at their ends. With
// `axes` (the volume's), each axis edge long enough in the picture gets ticks at round values of
// its coordinates, labelled ("10E", "45N", "850"; coordinate_label) outside the box where the
// picture has room, else just inside it, so that a map says where it is; the labels are in the
// fixed 5x7 font, the same pixels from every command.
// With `markers` (the grid points draw_markers will dot), a tick label a dot would cover is left out.
void draw_box_outline(Image& image, const VolumeGeometry& geometry, const RenderSettings& settings,
                      const std::array<GridAxis, 3>* axes = nullptr, const std::vector<GridIndex>& markers = {});

// The radius of a marker's dot on a width x height picture (draw_markers).
double marker_radius(uint32_t width, uint32_t height);

}  // namespace tfm
