// DiffDVR gradients: the GPU backward pass (inversion trick) against central finite differences
// of the double-precision CPU renderer and against a CPU reverse mode that stores every sample,
// for l2 and l1, cameras straight down the up axis and oblique, rays that miss the volume, leave
// it, or stop early; NaNs, split fields, odd image sizes, and the optical-depth clamp.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "test_data.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/reference/cpu_renderer.h"
#include "tfmatch/reference/diffdvr_cpu.h"
#include "tfmatch/solvers/solver_diffdvr.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

Volume wavy_volume(std::array<uint64_t, 3> dims, std::array<double, 3> spacing, uint32_t seed, int nan_every = 0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> noise(-0.05f, 0.05f);
  return test::make_volume(dims, spacing, "wavy volume", [&](uint64_t x, uint64_t y, uint64_t z, uint64_t i) {
    const float v =
        0.5f + 0.4f * std::sin(0.9f * x + 0.4f * y + 0.1f * seed) * std::cos(0.6f * z - 0.3f * x) + noise(rng);
    return nan_every && i % nan_every == 5 ? NAN : v;
  });
}

using test::random_tf;

struct Case {
  Volume ref, opt;
  TransferFunction ref_tf, tf;
  FieldRange range{0.0, 1.0};
  RenderSettings settings;  // width, height and optical model; the pose comes from `cameras`
  std::vector<OrbitCamera> cameras;
  ImageLoss loss = ImageLoss::L2;
};

OrbitCamera camera(double azimuth, double elevation) {
  OrbitCamera c;
  c.azimuth_deg = azimuth;
  c.elevation_deg = elevation;
  c.distance = 2.2;  // close enough that the box fills most of the image, far enough to miss at the corners
  c.fov_deg = 40;
  return c;
}

Case make_case(ImageLoss loss, double opacity_scale, TransferFunction ref_tf, TransferFunction tf) {
  Case c;
  c.ref = wavy_volume({9, 7, 6}, {1.0, 1.0, 1.5}, 1);
  c.opt = wavy_volume({9, 7, 6}, {1.0, 1.0, 1.5}, 2);
  c.ref_tf = std::move(ref_tf);
  c.tf = std::move(tf);
  c.settings.width = 24;
  c.settings.height = 24;
  c.settings.step_voxels = 0.43;
  c.settings.opacity_scale = opacity_scale;
  // Straight down the up axis, oblique from above and below, along a grid axis.
  c.cameras = {camera(0, 90), camera(30, 20), camera(200, -35), camera(90, 0)};
  c.loss = loss;
  return c;
}

RenderSettings with_camera(const RenderSettings& s, const OrbitCamera& cam) {
  RenderSettings out = s;
  out.camera = cam;
  return out;
}

ImageLossGradient gpu_gradient(Context& ctx, const Case& c, uint64_t max_chunk_voxels = 0,
                               ReductionMode reduction = ReductionMode::Auto,
                               uint32_t max_group_views = 64) {
  const VolumeGeometry geo = VolumeGeometry::from(c.opt.dims, c.opt.spacing);
  DeviceField ref(ctx, c.ref.values, "test reference", max_chunk_voxels);
  DeviceField opt(ctx, c.opt.values, "test field", max_chunk_voxels);
  Buffer ref_tf = upload_tf(ctx, c.ref_tf, "test reference TF");
  DiffDvrGradient g(ctx, ref, opt, geo, make_mapping(c.range, uint32_t(c.ref_tf.size())), ref_tf,
                    make_mapping(c.range, uint32_t(c.tf.size())), c.settings, c.loss, reduction, max_group_views);
  return g.evaluate(c.tf, c.cameras);
}

// The CPU side: target images, the reverse-mode gradient and the loss as a function of the TF.
struct CpuSide {
  explicit CpuSide(const Case& c) : c(c) {
    for (const OrbitCamera& cam : c.cameras) {
      targets.push_back(render_cpu(c.ref, c.ref_tf, c.range, with_camera(c.settings, cam)).rgba);
      const std::vector<double> x = render_cpu(c.opt, c.tf, c.range, with_camera(c.settings, cam)).rgba;
      signs.emplace_back(x.size());
      for (size_t i = 0; i < x.size(); ++i) signs.back()[i] = x[i] > targets.back()[i] ? 1 : (x[i] < targets.back()[i] ? -1 : 0);
    }
  }
  // The loss of the CPU renderer's images with `tf`. For l1 the signs of X - R are frozen at
  // the base TF: equal to the l1 loss while no component crosses 0, with the same derivative
  // there, and free of the kink a difference quotient could straddle.
  double loss(const TransferFunction& tf) const {
    double sum = 0.0;
    for (size_t v = 0; v < c.cameras.size(); ++v) {
      const std::vector<double> x = render_cpu(c.opt, tf, c.range, with_camera(c.settings, c.cameras[v])).rgba;
      if (c.loss == ImageLoss::L2) {
        sum += image_loss(x, targets[v], c.loss);
      } else {
        for (size_t i = 0; i < x.size(); ++i) sum += signs[v][i] * (x[i] - targets[v][i]);
      }
    }
    return sum;
  }
  // Reverse mode summed over the cameras, as 4j + c.
  std::vector<double> gradient(double* loss_out = nullptr) const {
    std::vector<double> g(c.tf.size() * 4, 0.0);
    double loss = 0.0;
    for (size_t v = 0; v < c.cameras.size(); ++v) {
      const CpuLossGradient r = image_loss_gradient_cpu(c.opt, c.tf, c.range, with_camera(c.settings, c.cameras[v]),
                                                        targets[v], c.loss);
      loss += r.loss;
      for (size_t j = 0; j < c.tf.size(); ++j)
        for (int ch = 0; ch < 4; ++ch) g[4 * j + ch] += r.gradient[j][ch];
    }
    if (loss_out) *loss_out = loss;
    return g;
  }
  const Case& c;
  std::vector<std::vector<double>> targets;
  std::vector<std::vector<double>> signs;  // of X - R at the base TF
};

// Central differences of the CPU renderer's loss, step h per TF entry.
std::vector<double> finite_differences(const CpuSide& cpu, double h) {
  std::vector<double> g(cpu.c.tf.size() * 4);
  for (size_t j = 0; j < cpu.c.tf.size(); ++j)
    for (int ch = 0; ch < 4; ++ch) {
      TransferFunction plus = cpu.c.tf, minus = cpu.c.tf;
      plus.rgba[j][ch] += h;
      minus.rgba[j][ch] -= h;
      g[4 * j + ch] = (cpu.loss(plus) - cpu.loss(minus)) / (2 * h);
    }
  return g;
}

double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

// |a - b| <= tol * max|b| for every entry; prints the worst relative error.
void expect_close(const std::vector<double>& a, const std::vector<double>& b, double tol, const char* what) {
  ASSERT_EQ(a.size(), b.size());
  const double scale = max_abs(b);
  ASSERT_GT(scale, 0.0) << what << ": the gradient is zero, the case tests nothing";
  double worst = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, std::abs(a[i] - b[i]) / scale);
    EXPECT_LE(std::abs(a[i] - b[i]), tol * scale)
        << what << ": entry " << i / 4 << " channel " << i % 4 << ": " << a[i] << " vs " << b[i];
  }
  std::printf("%s: max |difference| / max |gradient| = %.3g (bound %.1g)\n", what, worst, tol);
}

// Preconditions of the comparison: no pixel where float and double, or the perturbed TFs, could
// take different discrete decisions. Termination: T within 1e-7 of the threshold (CPU ambiguity
// tracking); a perturbation of h = 1e-6 moves T by less than 1e-8 here, and float T is good to
// ~1e-6 relative, 1e-8 at the threshold. Sample count: (t_exit - t_entry) / dt within 3e-5 of a
// half integer, where float ray setup (~1e-5 here) could round the other way. For l1: no
// |X - R| below 5e-6, where float images (within 2e-6 of the CPU's) could take the other sign.
void check_case_is_smooth(const CpuSide& cpu, size_t* stopped_early, size_t* missed, size_t* exited) {
  const Case& c = cpu.c;
  for (size_t v = 0; v < c.cameras.size(); ++v) {
    CpuRenderOptions o;
    o.track_ambiguity = true;
    o.ambiguity_tolerance = 1e-7;
    const RenderSettings s = with_camera(c.settings, c.cameras[v]);
    const CpuRender r = render_cpu(c.opt, c.tf, c.range, s, o);
    const VolumeGeometry geo = VolumeGeometry::from(c.opt.dims, c.opt.spacing);
    const MarchConstants m = march_constants(s, geo);
    const CameraFrame frame = orbit_frame(s.camera, geo, s.width, s.height);
    for (size_t p = 0; p < r.stop.size(); ++p) {
      ASSERT_FALSE(r.ambiguous[p]) << "camera " << v << " pixel " << p << ": termination ambiguous";
      const RaySegment ray =
          pixel_ray(frame, geo, m, uint32_t(p % s.width), uint32_t(p / s.width), s.width, s.height, 3e-5);
      ASSERT_FALSE(ray.steps_ambiguous) << "camera " << v << " pixel " << p << ": sample count ambiguous";
      if (ray.steps == 0) {
        ++*missed;
        continue;
      }
      if (r.stop[p] < ray.steps) ++*stopped_early;
      else ++*exited;
      if (c.loss == ImageLoss::L1)
        for (int ch = 0; ch < 4; ++ch)
          ASSERT_GT(std::abs(r.rgba[4 * p + ch] - cpu.targets[v][4 * p + ch]), 5e-6)
              << "camera " << v << " pixel " << p << ": |X - R| too close to the l1 kink for float";
    }
  }
}

class DiffDvrGradientTest : public test::GpuTest {
 protected:
  // h = 1e-6: double rounding of a loss of ~10^2 over 2h is ~1e-8, far below the bounds below,
  // and second-order truncation is ~h^2.
  //
  // Bounds, relative to the largest gradient entry (terms of both signs cancel in single
  // entries). CPU reverse mode vs differences: 1e-6 (both double; what is left is the
  // differences' rounding, ~1e-8). GPU vs differences: 5e-5. The GPU rounds the TF coordinate
  // x = (v - lo) scale in float (|dw| <= 2^-24 x: 4e-7 for N = 7), sample positions and
  // trilinear weights (~1e-7), exp() (a few ulp), and T recovered by K ~ 30 divisions drifts by
  // ~K ulp (2e-6); its target images are its own float renders (within 2e-6 of the CPU's).
  // Lavapipe lands below 1e-6 (printed); the bound leaves room for other drivers' exp and FMA.
  void check(const Case& c, size_t* stopped_early = nullptr, size_t* exited = nullptr) {
    const double h = 1e-6;
    const CpuSide cpu(c);
    size_t early = 0, missed = 0, out = 0;
    check_case_is_smooth(cpu, &early, &missed, &out);
    EXPECT_GT(missed, 0u) << "no ray misses the volume";
    if (stopped_early) *stopped_early = early;
    if (exited) *exited = out;
    double cpu_loss = 0;
    const std::vector<double> reverse = cpu.gradient(&cpu_loss);
    const std::vector<double> fd = finite_differences(cpu, h);
    expect_close(reverse, fd, 1e-6, "CPU reverse mode vs central differences");
    // The device's own choice (private histograms on lavapipe) and the GPUs' runs path.
    for (ReductionMode mode : {ReductionMode::Auto, ReductionMode::RunsShared}) {
      SCOPED_TRACE(reduction_mode_name(mode));
      const ImageLossGradient gpu = gpu_gradient(ctx(), c, 0, mode);
      expect_close(gpu.gradient, fd, 5e-5, "GPU backward pass vs central differences");
      EXPECT_NEAR(gpu.loss, cpu_loss, 1e-4 * cpu_loss) << "GPU and CPU losses";
      EXPECT_EQ(gpu.components, uint64_t(c.settings.width) * c.settings.height * c.cameras.size() * 4);
    }
  }
};

TEST_F(DiffDvrGradientTest, L2MatchesFiniteDifferencesWhenRaysLeaveTheVolume) {
  size_t early = 0, exited = 0;
  check(make_case(ImageLoss::L2, 4.0, random_tf(9, 3, 0.1, 0.9, 0.1, 0.9), random_tf(7, 4, 0.1, 0.9, 0.1, 0.9)), &early,
        &exited);
  EXPECT_GT(exited, 100u) << "the case should have rays that march through the whole volume";
}

TEST_F(DiffDvrGradientTest, L2MatchesFiniteDifferencesWhenRaysTerminateEarly) {
  size_t early = 0, exited = 0;
  check(make_case(ImageLoss::L2, 80.0, random_tf(9, 3, 0.1, 0.9, 0.5, 0.95), random_tf(7, 4, 0.1, 0.9, 0.5, 0.95)),
        &early, &exited);
  EXPECT_GT(early, 100u) << "the case should have rays that stop at the termination opacity";
}

TEST_F(DiffDvrGradientTest, L1MatchesFiniteDifferences) {
  size_t early = 0, exited = 0;
  // The reference is more opaque and redder in every channel than the field can be, so every
  // covered pixel has X - R clearly away from 0 (the l1 kink) in all four components.
  check(make_case(ImageLoss::L1, 20.0, random_tf(9, 3, 0.6, 0.9, 0.6, 0.9), random_tf(7, 4, 0.1, 0.4, 0.1, 0.4)),
        &early, &exited);
  EXPECT_GT(early, 10u);
  EXPECT_GT(exited, 10u);
}

// Rays of ~20 000, ~65 200 and ~80 000 samples down 3 x 3 columns: too long for a CPU device's
// private lanes (4 rays each past llvmpipe's 65535 loop iterations), so Auto takes a runs path
// there, as on a GPU, marched flat (one loop iteration a sample; the second column is within 70
// of the limit, where the nested march's bound of 10 a sample is far past it, and the third is
// marched back in two parts on llvmpipe, its rays' states kept between them). The gradient
// matches the CPU reverse mode within what float drift allows: T recovered by K divisions and the
// forward pass's C and T drift by up to ~K float ulps each (2K 2^-24: 2.4e-3, 7.8e-3 and 9.5e-3;
// lavapipe 7e-4, 6e-3 and printed), where the short rays above drift by ~30. No ray stops early
// (opacity scale per length), so every sample is marched.
TEST_F(DiffDvrGradientTest, LongRaysMatchTheReverseModeOnThePathTheyFit) {
  const std::pair<uint64_t, double> columns[] = {{1000, 2.0}, {3260, 0.6}, {4000, 0.5}};
  for (const auto& [length, opacity] : columns) {
    SCOPED_TRACE(length);
    Case c;
    c.ref = wavy_volume({3, 3, length}, {1.0, 1.0, 1.0}, 1);
    c.opt = wavy_volume({3, 3, length}, {1.0, 1.0, 1.0}, 2);
    c.ref_tf = random_tf(9, 3, 0.1, 0.9, 0.1, 0.9);
    c.tf = random_tf(7, 4, 0.1, 0.9, 0.1, 0.9);
    c.settings.width = c.settings.height = 3;
    c.settings.step_voxels = 0.05;
    c.settings.opacity_scale = opacity;
    OrbitCamera down;
    down.elevation_deg = 90;
    down.fov_deg = 0.5;
    c.cameras = {down};
    const MarchConstants m = march_constants(c.settings, VolumeGeometry::from(c.opt.dims, c.opt.spacing));
    ASSERT_GT(m.max_steps, uint32_t(length * 19));
    const ReductionMode chosen = DiffDvrBackwardKernel::choose(ctx(), 7, ReductionMode::Auto, m.max_steps);
    if (ctx().loop_iteration_limit() != 0) {
      EXPECT_NE(chosen, ReductionMode::Private) << "4 rays a lane do not fit";
      const uint64_t other = DiffDvrBackwardKernel::other_loops(chosen, 7);
      EXPECT_EQ(march_parts(ctx(), m.max_steps, other).size(), length == 4000 ? 2u : 1u);
      if (length == 3260) {
        EXPECT_FALSE(march_loops_fit(ctx(), m.max_steps + 100, 1, other)) << "the case should sit at the limit";
        const uint32_t nested = DiffDvrBackwardKernel::loops_per_sample(chosen, RunsMarch::Nested);
        EXPECT_FALSE(march_loops_fit(ctx(), m.max_steps, nested, other)) << "nested runs would not fit";
      }
    }
    const CpuSide cpu(c);
    size_t early = 0, missed = 0, exited = 0;
    check_case_is_smooth(cpu, &early, &missed, &exited);
    EXPECT_EQ(early, 0u);
    EXPECT_GT(exited, 0u);
    double cpu_loss = 0;
    const std::vector<double> reverse = cpu.gradient(&cpu_loss);
    const ImageLossGradient gpu = gpu_gradient(ctx(), c);
    // Each float image (the field's and the reference's) may drift by K ulps over K samples.
    const double drift = 2.0 * m.max_steps * 0x1p-24, n = 4.0 * c.settings.width * c.settings.height;
    expect_close(gpu.gradient, reverse, 1.25 * drift + 2e-3, "GPU backward pass on long rays vs CPU reverse mode");
    // The loss: what that drift makes of sum (X - R)^2 over its n components.
    EXPECT_NEAR(gpu.loss, cpu_loss, 2 * drift * std::sqrt(n * cpu_loss) + n * drift * drift);
  }
}

// Reference images rendered once into the pool and reused give the same loss and gradient bits
// as rendering them with each evaluation, whatever the order in which pool cameras are chosen.
TEST_F(DiffDvrGradientTest, PooledReferenceViewsGiveTheSameBits) {
  const Case c = make_case(ImageLoss::L2, 20.0, random_tf(9, 3, 0.1, 0.9, 0.1, 0.9), random_tf(7, 4, 0.1, 0.9, 0.1, 0.9));
  const VolumeGeometry geo = VolumeGeometry::from(c.opt.dims, c.opt.spacing);
  DeviceField ref(ctx(), c.ref.values, "test reference"), opt(ctx(), c.opt.values, "test field");
  Buffer ref_tf = upload_tf(ctx(), c.ref_tf, "test reference TF");
  DiffDvrGradient g(ctx(), ref, opt, geo, make_mapping(c.range, uint32_t(c.ref_tf.size())), ref_tf,
                    make_mapping(c.range, uint32_t(c.tf.size())), c.settings, c.loss, ReductionMode::Auto, 3);
  g.set_view_pool(c.cameras);
  ASSERT_EQ(g.pool_size(), c.cameras.size());
  const std::vector<uint32_t> order = {2, 0, 3, 1};
  std::vector<OrbitCamera> cameras;
  for (uint32_t i : order) cameras.push_back(c.cameras[i]);
  const ImageLossGradient rendered = g.evaluate(c.tf, cameras);
  const ImageLossGradient pooled = g.evaluate_pooled(c.tf, order);
  EXPECT_EQ(pooled.loss, rendered.loss);
  ASSERT_EQ(pooled.gradient.size(), rendered.gradient.size());
  EXPECT_EQ(std::memcmp(pooled.gradient.data(), rendered.gradient.data(), pooled.gradient.size() * sizeof(double)), 0);
  EXPECT_THROW(g.evaluate_pooled(c.tf, std::vector<uint32_t>{4}), std::invalid_argument);
  // A stop asked for while the pool renders ends it between submissions (a pool of hundreds of
  // views held a Ctrl-C past the viewer's 20 s grace), leaving no pool rather than part of one.
  request_cancel(SIGINT);
  EXPECT_THROW(g.set_view_pool(c.cameras), Cancelled);
  reset_cancel();
  EXPECT_EQ(g.pool_size(), 0u);
}

}  // namespace
}  // namespace tfm
