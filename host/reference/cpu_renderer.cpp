// The CPU reference renderer.
#include "tfmatch/reference/cpu_renderer.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "tfmatch/model/field_mapping.h"

namespace tfm {

Rgba classify_cpu(const TransferFunction& tf, const FieldRange& range, double v) {
  const size_t n = tf.size();
  const double x = std::clamp((v - range.lo) / (range.hi - range.lo), 0.0, 1.0) * double(n - 1);
  const size_t j = std::min<size_t>(static_cast<size_t>(std::floor(x)), n - 2);
  const double w = x - double(j);
  Rgba c;
  for (int k = 0; k < 4; ++k) c[k] = std::clamp((1.0 - w) * tf.rgba[j][k] + w * tf.rgba[j + 1][k], 0.0, 1.0);
  return c;
}

bool nan_status_ambiguous(const Volume& vol, const glm::dvec3& p, double eps) {
  double v;
  const bool base = sample_trilinear(vol, p, v);
  for (int a = 0; a < 3; ++a)
    for (double s : {-eps, eps}) {
      glm::dvec3 q = p;
      q[a] += s;
      if (sample_trilinear(vol, q, v) != base) return true;
    }
  return false;
}

bool sample_trilinear(const Volume& vol, const glm::dvec3& p, double& value) {
  value = 0.0;
  uint64_t i0[3], i1[3];
  double w[3];
  for (int a = 0; a < 3; ++a) {
    const double top = double(vol.dims[a] - 1);
    const double q = std::clamp(p[a], 0.0, top);
    const double f = std::floor(q);
    w[a] = q - f;
    i0[a] = static_cast<uint64_t>(f);
    i1[a] = std::min<uint64_t>(i0[a] + 1, vol.dims[a] - 1);
  }
  double c[2][2][2];
  for (int dz = 0; dz < 2; ++dz)
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx) {
        const float f = vol.at(dx ? i1[0] : i0[0], dy ? i1[1] : i0[1], dz ? i1[2] : i0[2]);
        if (no_data(f)) return false;
        c[dz][dy][dx] = f;
      }
  auto lerp = [](double a, double b, double t) { return a + t * (b - a); };
  const double y0 = lerp(lerp(c[0][0][0], c[0][0][1], w[0]), lerp(c[0][1][0], c[0][1][1], w[0]), w[1]);
  const double y1 = lerp(lerp(c[1][0][0], c[1][0][1], w[0]), lerp(c[1][1][0], c[1][1][1], w[0]), w[1]);
  value = lerp(y0, y1, w[2]);
  return true;
}

CpuRender render_cpu(const Volume& vol, const TransferFunction& tf, const FieldRange& range,
                     const RenderSettings& s, const CpuRenderOptions& o) {
  if (tf.size() < 2) throw std::runtime_error("render: the transfer function needs at least 2 entries");
  if (!(range.hi > range.lo)) throw std::runtime_error("render: empty field range");
  const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing, s.z_scale);
  const MarchConstants march = march_constants(s, geo);
  const CameraFrame frame = orbit_frame(s.camera, geo, s.width, s.height);
  const bool has_nan = o.track_ambiguity && std::any_of(vol.values.begin(), vol.values.end(),
                                                        [](float v) { return no_data(v); });
  const double tol = o.ambiguity_tolerance;
  CpuRender out;
  out.width = s.width;
  out.height = s.height;
  out.rgba.assign(size_t(s.width) * s.height * 4, 0.0);
  out.stop.assign(size_t(s.width) * s.height, 0);
  if (o.track_ambiguity) out.ambiguous.assign(size_t(s.width) * s.height, 0);
  const uint32_t row_end = std::min(o.row_end, s.height);
  for (uint32_t py = o.row_begin; py < row_end; ++py) {
    for (uint32_t px = 0; px < s.width; ++px) {
      const RaySegment ray = pixel_ray(frame, geo, march, px, py, s.width, s.height, tol);
      const size_t pixel = size_t(py) * s.width + px;
      bool ambiguous = ray.steps_ambiguous;
      double color[3] = {0, 0, 0}, transmittance = 1.0;
      uint32_t k = 0;
      while (k < ray.steps) {
        const glm::dvec3 p = ray.entry + ((k + 0.5) * march.dt) * ray.dir;
        double value;
        if (has_nan && nan_status_ambiguous(vol, p, tol)) ambiguous = true;
        if (sample_trilinear(vol, p, value)) {
          const Rgba c = classify_cpu(tf, range, value);
          const double tau = std::exp(-std::min(c[3] * march.depth_per_alpha * ray.depth_scale, kMaxSampleOpticalDepth));
          for (int ch = 0; ch < 3; ++ch) color[ch] += transmittance * (1.0 - tau) * c[ch];
          transmittance *= tau;
        }
        ++k;
        if (std::abs(transmittance - march.stop_transmittance) < tol) ambiguous = true;
        if (transmittance <= march.stop_transmittance) break;
      }
      for (int ch = 0; ch < 3; ++ch) out.rgba[4 * pixel + ch] = color[ch];
      out.rgba[4 * pixel + 3] = 1.0 - transmittance;
      out.stop[pixel] = k;
      out.samples += k;
      if (o.track_ambiguity) out.ambiguous[pixel] = ambiguous;
    }
    if (o.progress) o.progress(py + 1 - o.row_begin);
  }
  return out;
}

}  // namespace tfm
