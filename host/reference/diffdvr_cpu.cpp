// Reverse-mode DiffDVR in double precision, storing every sample.
#include "tfmatch/reference/diffdvr_cpu.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "tfmatch/model/camera.h"
#include "tfmatch/reference/cpu_renderer.h"

namespace tfm {
namespace {

// What the backward walk needs of one non-empty sample.
struct Sample {
  double transmittance;  // T before the sample
  double tau;
  Rgba colour;           // clamped TF value
  size_t j;
  double w;
  bool depth_clamped;
};

double loss_derivative(double diff, ImageLoss loss) {
  if (loss == ImageLoss::L2) return 2.0 * diff;
  return diff > 0 ? 1.0 : (diff < 0 ? -1.0 : 0.0);
}

double loss_term(double diff, ImageLoss loss) { return loss == ImageLoss::L2 ? diff * diff : std::abs(diff); }

}  // namespace

double image_loss(std::span<const double> image, std::span<const double> target, ImageLoss loss) {
  if (image.size() != target.size()) throw std::runtime_error("image loss: images differ in size");
  double sum = 0.0;
  for (size_t i = 0; i < image.size(); ++i) sum += loss_term(image[i] - target[i], loss);
  return sum;
}

CpuLossGradient image_loss_gradient_cpu(const Volume& vol, const TransferFunction& tf, const FieldRange& range,
                                        const RenderSettings& s, std::span<const double> target, ImageLoss loss) {
  if (tf.size() < 2) throw std::runtime_error("diffdvr: the transfer function needs at least 2 entries");
  if (!(range.hi > range.lo)) throw std::runtime_error("diffdvr: empty field range");
  if (target.size() != size_t(s.width) * s.height * 4) throw std::runtime_error("diffdvr: target image size differs");
  const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing, s.z_scale);
  const MarchConstants march = march_constants(s, geo);
  const CameraFrame frame = orbit_frame(s.camera, geo, s.width, s.height);
  const size_t n = tf.size();
  CpuLossGradient out;
  out.gradient.assign(n, Rgba{0, 0, 0, 0});
  out.rgba.assign(size_t(s.width) * s.height * 4, 0.0);
  out.stop.assign(size_t(s.width) * s.height, 0);
  std::vector<Sample> record;
  for (uint32_t py = 0; py < s.height; ++py)
    for (uint32_t px = 0; px < s.width; ++px) {
      const size_t pixel = size_t(py) * s.width + px;
      const RaySegment ray = pixel_ray(frame, geo, march, px, py, s.width, s.height);
      // Forward, as render_cpu marches (same positions, mapping, clamps and termination).
      record.clear();
      double colour[3] = {0, 0, 0}, trans = 1.0;
      uint32_t k = 0;
      while (k < ray.steps) {
        const glm::dvec3 p = ray.entry + ((k + 0.5) * march.dt) * ray.dir;
        double value;
        if (sample_trilinear(vol, p, value)) {
          const double x = std::clamp((value - range.lo) / (range.hi - range.lo), 0.0, 1.0) * double(n - 1);
          const size_t j = std::min<size_t>(static_cast<size_t>(std::floor(x)), n - 2);
          const double w = x - double(j);
          Sample smp{trans, 0.0, {}, j, w, false};
          for (int c = 0; c < 4; ++c)
            smp.colour[c] = std::clamp((1.0 - w) * tf.rgba[j][c] + w * tf.rgba[j + 1][c], 0.0, 1.0);
          const double depth = smp.colour[3] * march.depth_per_alpha * ray.depth_scale;
          smp.depth_clamped = depth >= kMaxSampleOpticalDepth;
          smp.tau = std::exp(-std::min(depth, kMaxSampleOpticalDepth));
          for (int c = 0; c < 3; ++c) colour[c] += trans * (1.0 - smp.tau) * smp.colour[c];
          trans *= smp.tau;
          record.push_back(smp);
        }
        ++k;
        if (trans <= march.stop_transmittance) break;
      }
      out.stop[pixel] = k;
      out.samples += k;
      const double x[4] = {colour[0], colour[1], colour[2], 1.0 - trans};
      double g[4];
      for (int c = 0; c < 4; ++c) {
        out.rgba[4 * pixel + c] = x[c];
        const double diff = x[c] - target[4 * pixel + c];
        out.loss += loss_term(diff, loss);
        g[c] = loss_derivative(diff, loss);
      }
      // Backward over the stored samples: adjoints of C (constant) and of T.
      double g_trans = -g[3];
      for (auto it = record.rbegin(); it != record.rend(); ++it) {
        const Sample& smp = *it;
        const double gc_dot_c = g[0] * smp.colour[0] + g[1] * smp.colour[1] + g[2] * smp.colour[2];
        Rgba d;
        for (int c = 0; c < 3; ++c) d[c] = g[c] * smp.transmittance * (1.0 - smp.tau);
        const double d_tau = smp.transmittance * (g_trans - gc_dot_c);
        d[3] = smp.depth_clamped ? 0.0 : -d_tau * march.depth_per_alpha * ray.depth_scale * smp.tau;
        g_trans = (1.0 - smp.tau) * gc_dot_c + smp.tau * g_trans;
        for (int c = 0; c < 4; ++c) {
          out.gradient[smp.j][c] += (1.0 - smp.w) * d[c];
          out.gradient[smp.j + 1][c] += smp.w * d[c];
        }
      }
    }
  return out;
}

}  // namespace tfm
