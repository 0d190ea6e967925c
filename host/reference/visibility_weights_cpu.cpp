// The CPU reference of the visibility weights.
#include "tfmatch/reference/visibility_weights_cpu.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "tfmatch/model/field_mapping.h"
#include "tfmatch/reference/cpu_renderer.h"
#include "tfmatch/shaders/visibility_layout.h"

namespace tfm {

namespace {

// T_v(x) of the voxel at index-space point p for the camera frame f.
// With `ambiguous` (NaN in the volume), sets it when a sample's NaN status is ambiguous.
double transmittance_to_eye(const Volume& vol, const TransferFunction& tf, const FieldRange& range,
                            const VolumeGeometry& geo, const MarchConstants& march, const CameraFrame& f,
                            const glm::dvec3& p, bool* ambiguous, double tolerance) {
  const glm::dvec3 x = p * geo.axis_scale;
  const glm::dvec3 rel = x - f.eye;
  const double depth = glm::dot(rel, f.forward);
  if (!(depth > 0.0)) return 0.0;
  if (std::abs(glm::dot(rel, f.right)) > depth * f.tan_half_fov * f.aspect ||
      std::abs(glm::dot(rel, f.up)) > depth * f.tan_half_fov)
    return 0.0;
  const double dist = glm::length(rel);
  const glm::dvec3 d = (-rel / dist) / geo.axis_scale;  // index space per world unit, towards the eye
  double t1 = dist;
  for (int a = 0; a < 3; ++a) {
    const double hi = double(vol.dims[size_t(a)]) - 0.5;
    if (d[a] > 1e-30) t1 = std::min(t1, (hi - p[a]) / d[a]);
    if (d[a] < -1e-30) t1 = std::min(t1, (-0.5 - p[a]) / d[a]);
  }
  const double steps = std::min(t1 / march.dt, double(march.max_steps));
  const uint32_t whole = uint32_t(steps);
  double transmittance = 1.0;
  for (uint32_t k = 1; k <= whole + 1; ++k) {
    const double part = k <= whole ? 1.0 : steps - whole;  // the last sample: its fraction of a step
    double value;
    if (!(part > 0.0)) continue;
    const glm::dvec3 q = p + (k * march.dt) * d;
    if (ambiguous && nan_status_ambiguous(vol, q, tolerance)) *ambiguous = true;
    if (!sample_trilinear(vol, q, value)) continue;
    const double a = classify_cpu(tf, range, value)[3];
    transmittance *= std::exp(-std::min(a * march.depth_per_alpha, kMaxSampleOpticalDepth) * part);
    if (transmittance < double(float(TFM_VIS_MIN_TRANSMITTANCE))) return 0.0;
  }
  return transmittance;
}

}  // namespace

CpuVisibilityWeights visibility_weights_cpu(const Volume& vol, const TransferFunction& tf, const FieldRange& range,
                                            const RenderSettings& settings, std::span<const OrbitCamera> cameras,
                                            bool track_ambiguity, double tolerance) {
  if (cameras.empty()) throw std::invalid_argument("visibility_weights_cpu: no cameras");
  if (tf.size() < 2) throw std::runtime_error("visibility_weights_cpu: the TF needs at least 2 entries");
  const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing, settings.z_scale);
  const MarchConstants march = march_constants(settings, geo);
  std::vector<CameraFrame> frames;
  for (const OrbitCamera& c : cameras) frames.push_back(orbit_frame(c, geo, settings.width, settings.height));
  CpuVisibilityWeights out;
  out.weights.assign(vol.values.size(), 0.0);
  const bool has_nan =
      track_ambiguity && std::any_of(vol.values.begin(), vol.values.end(), [](float v) { return no_data(v); });
  if (track_ambiguity) out.ambiguous.assign(vol.values.size(), 0);
  const uint64_t nx = vol.dims[0], ny = vol.dims[1];
  for (uint64_t i = 0; i < vol.values.size(); ++i) {
    const glm::dvec3 p(double(i % nx), double((i / nx) % ny), double(i / (nx * ny)));
    double sum = 0.0;
    bool ambiguous = false;
    for (const CameraFrame& f : frames)
      sum += transmittance_to_eye(vol, tf, range, geo, march, f, p, has_nan ? &ambiguous : nullptr, tolerance);
    out.weights[i] = sum;
    if (ambiguous) out.ambiguous[i] = 1;
    out.max_sum = std::max(out.max_sum, sum);
  }
  if (out.max_sum > 0.0)
    for (double& w : out.weights) w /= out.max_sum;
  return out;
}

}  // namespace tfm
