// DiffDVR's GPU backward pass against the CPU reverse mode that stores every sample, on the
// configurations finite differences cannot probe well (NaNs, fields split over buffers, the
// optical-depth clamp near alpha = 1, odd image and TF sizes), and the bit-identity of the
// shared-memory and global-atomics paths and of every split of the views into groups.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <vector>

#include "test_data.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/reference/cpu_renderer.h"
#include "tfmatch/reference/diffdvr_cpu.h"
#include "tfmatch/solvers/solver_diffdvr.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

Volume noisy_volume(std::array<uint64_t, 3> dims, uint32_t seed, int nan_every = 0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  return test::make_volume(dims, {1.0, 1.0, 1.0}, "noisy volume", [&](uint64_t x, uint64_t, uint64_t, uint64_t i) {
    const float v = 0.6f * u(rng) + 0.4f * float(x) / float(dims[0]);
    return nan_every && i % nan_every == 2 ? NAN : v;
  });
}

using test::random_tf;

struct Scene {
  Volume ref, opt;
  TransferFunction ref_tf, tf;
  RenderSettings settings;
  std::vector<OrbitCamera> cameras;
  ImageLoss loss = ImageLoss::L2;
};

std::vector<OrbitCamera> cameras() {
  std::vector<OrbitCamera> out;
  for (auto [az, el] : {std::pair{15.0, 90.0}, {40.0, 25.0}, {250.0, -60.0}}) {
    OrbitCamera c;
    c.azimuth_deg = az;
    c.elevation_deg = el;
    c.distance = 2.3;
    c.fov_deg = 40;
    out.push_back(c);
  }
  return out;
}

Scene make_scene(std::array<uint64_t, 3> dims, uint32_t tf_size, uint32_t width, uint32_t height, int nan_every = 0) {
  Scene s;
  s.ref = noisy_volume(dims, 11, nan_every);
  s.opt = noisy_volume(dims, 12, nan_every);
  s.ref_tf = random_tf(5, 13);
  s.tf = random_tf(tf_size, 14);
  s.settings.width = width;
  s.settings.height = height;
  s.settings.step_voxels = 0.61;
  s.settings.opacity_scale = 10.0;
  s.cameras = cameras();
  return s;
}

ImageLossGradient gpu(Context& ctx, const Scene& s, uint64_t max_chunk_voxels = 0,
                      ReductionMode reduction = ReductionMode::Auto,
                      uint32_t max_group_views = 64, uint32_t* passes = nullptr) {
  const VolumeGeometry geo = VolumeGeometry::from(s.opt.dims, s.opt.spacing);
  DeviceField ref(ctx, s.ref.values, "reverse test reference", max_chunk_voxels);
  DeviceField opt(ctx, s.opt.values, "reverse test field", max_chunk_voxels);
  Buffer ref_tf = upload_tf(ctx, s.ref_tf, "reverse test reference TF");
  DiffDvrGradient g(ctx, ref, opt, geo, make_mapping({0, 1}, uint32_t(s.ref_tf.size())), ref_tf,
                    make_mapping({0, 1}, uint32_t(s.tf.size())), s.settings, s.loss, reduction, max_group_views);
  ImageLossGradient out = g.evaluate(s.tf, s.cameras);
  if (passes) *passes = g.last_pass_count();
  return out;
}

struct CpuTotal {
  double loss = 0;
  std::vector<double> gradient;
  uint64_t clamped_samples = 0;
};

CpuTotal cpu(const Scene& s) {
  CpuTotal t;
  t.gradient.assign(s.tf.size() * 4, 0.0);
  for (const OrbitCamera& cam : s.cameras) {
    RenderSettings rs = s.settings;
    rs.camera = cam;
    const std::vector<double> target = render_cpu(s.ref, s.ref_tf, {0, 1}, rs).rgba;
    const CpuLossGradient r = image_loss_gradient_cpu(s.opt, s.tf, {0, 1}, rs, target, s.loss);
    t.loss += r.loss;
    for (size_t j = 0; j < s.tf.size(); ++j)
      for (int c = 0; c < 4; ++c) t.gradient[4 * j + c] += r.gradient[j][c];
  }
  return t;
}

class DiffDvrReverse : public test::GpuTest {
 protected:
  // GPU vs CPU reverse mode, relative to the largest gradient entry: 5e-5, the bound of the
  // finite-difference test (test_diffdvr_gradient.cpp explains it). The largest term here is the
  // float TF coordinate with N = 127: |dw| <= 2^-24 * 126 = 7.5e-6. Lavapipe: <= 1.3e-5 for
  // that case, ~1e-6 for the others (printed).
  // Every summing mode of the backward kernel the device runs: both runs paths and, with subgroup
  // arithmetic, the private histograms (lavapipe's default).
  std::vector<ReductionMode> modes() {
    std::vector<ReductionMode> out = {ReductionMode::RunsShared, ReductionMode::RunsGlobal};
    try {
      DiffDvrBackwardKernel(ctx(), 1, 2, ImageLoss::L2, ReductionMode::Private);
      out.push_back(ReductionMode::Private);
    } catch (const std::runtime_error& e) {
      std::printf("private histograms not tested: %s\n", e.what());
    }
    return out;
  }

  void compare(const Scene& s, uint64_t max_chunk_voxels = 0, uint32_t* passes = nullptr) {
    const CpuTotal want = cpu(s);
    for (ReductionMode mode : modes()) {
      SCOPED_TRACE(reduction_mode_name(mode));
      const ImageLossGradient got = gpu(ctx(), s, max_chunk_voxels, mode, 64, passes);
      ASSERT_EQ(got.gradient.size(), want.gradient.size());
      double scale = 0, worst = 0;
      for (double g : want.gradient) scale = std::max(scale, std::abs(g));
      ASSERT_GT(scale, 0.0) << "zero gradient: the case tests nothing";
      for (size_t i = 0; i < want.gradient.size(); ++i) {
        worst = std::max(worst, std::abs(got.gradient[i] - want.gradient[i]) / scale);
        EXPECT_LE(std::abs(got.gradient[i] - want.gradient[i]), 5e-5 * scale)
            << "entry " << i / 4 << " channel " << i % 4 << ": GPU " << got.gradient[i] << " CPU " << want.gradient[i];
      }
      EXPECT_NEAR(got.loss, want.loss, 1e-4 * want.loss);
      std::printf("%s: GPU vs CPU reverse mode: max |difference| / max |gradient| = %.3g\n",
                  reduction_mode_name(mode), worst);
    }
  }
};

TEST_F(DiffDvrReverse, MatchesWithNaNsAndAFieldSplitOverBuffers) {
  // 3 chunks of 200 voxels; every 17th voxel is NaN (empty samples around it).
  const Scene s = make_scene({10, 8, 7}, 13, 24, 24, 17);
  compare(s, 200);
}

TEST_F(DiffDvrReverse, MatchesWhereTheOpticalDepthClampIsActive) {
  // Opacity scale 3000 over a 9-voxel box: one step at TF opacity > 0.15 has optical depth > 20,
  // so its transmittance is clamped at exp(-20) and rays stop after one or two samples with
  // T ~ 1e-9: the inversion divides by tau ~ 2e-9 and must stay accurate.
  Scene s = make_scene({9, 7, 6}, 7, 24, 24);
  s.settings.opacity_scale = 3000.0;
  s.loss = ImageLoss::L1;
  const VolumeGeometry geo = VolumeGeometry::from(s.opt.dims, s.opt.spacing);
  const MarchConstants m = march_constants(s.settings, geo);
  ASSERT_GT(m.depth_per_alpha * 0.15, kMaxSampleOpticalDepth) << "the case must exercise the clamp";
  compare(s);
}

TEST_F(DiffDvrReverse, MatchesWhenTheSumsAreSplitIntoGroupsAndRowBands) {
  // An absurd opacity scale makes the accumulators' worst-case bound per ray (~10^7) so large
  // that DiffDvrGradient must sum each view separately and each in two bands of 16 rows.
  Scene s = make_scene({7, 6, 5}, 6, 24, 24);
  s.settings.opacity_scale = 1e6;
  uint32_t passes = 0;
  compare(s, 0, &passes);
  EXPECT_EQ(passes, 6u) << "3 views x 2 bands";
}

TEST_F(DiffDvrReverse, MatchesOnOddImageAndTfSizes) {
  compare(make_scene({6, 5, 4}, 2, 17, 13));  // one past the 16x16 tile in x; 2 TF entries
  compare(make_scene({5, 9, 3}, 127, 1, 1));  // a single pixel; N = 127
}

bool same_bits(const ImageLossGradient& a, const ImageLossGradient& b) {
  return a.loss == b.loss && a.gradient.size() == b.gradient.size() &&
         std::memcmp(a.gradient.data(), b.gradient.data(), a.gradient.size() * sizeof(double)) == 0;
}

TEST_F(DiffDvrReverse, SharedAndGlobalAtomicsAndViewGroupsGiveIdenticalBits) {
  const Scene s = make_scene({8, 8, 8}, 9, 20, 18);
  const ImageLossGradient shared = gpu(ctx(), s, 0, ReductionMode::RunsShared);
  EXPECT_TRUE(same_bits(shared, gpu(ctx(), s, 0, ReductionMode::RunsGlobal)));
  EXPECT_TRUE(same_bits(shared, gpu(ctx(), s, 0, ReductionMode::RunsShared, 1)));
  // A repeated evaluation (reference images reused) gives the same bits again.
  const VolumeGeometry geo = VolumeGeometry::from(s.opt.dims, s.opt.spacing);
  DeviceField ref(ctx(), s.ref.values, "ref"), opt(ctx(), s.opt.values, "opt");
  Buffer ref_tf = upload_tf(ctx(), s.ref_tf, "ref TF");
  DiffDvrGradient g(ctx(), ref, opt, geo, make_mapping({0, 1}, uint32_t(s.ref_tf.size())), ref_tf,
                    make_mapping({0, 1}, uint32_t(s.tf.size())), s.settings, s.loss, ReductionMode::RunsShared);
  const ImageLossGradient first = g.evaluate(s.tf, s.cameras), again = g.evaluate(s.tf, s.cameras);
  EXPECT_TRUE(same_bits(first, again));
  EXPECT_TRUE(same_bits(first, shared));
}

// The private histograms sum in another float grouping than the runs (close, not the same bits),
// but are deterministic: the same bits on every evaluation and for every split of the views into
// groups (a lane's pixels stay the same). A split into row bands that cuts a lane's 64 rows
// changes its float grouping, so bands are not covered here (the match with the CPU reference
// over 16-row bands is, in MatchesWhenTheSumsAreSplitIntoGroupsAndRowBands).
TEST_F(DiffDvrReverse, PrivateHistogramsGiveTheSameBitsOnEveryEvaluationAndViewGrouping) {
  const std::vector<ReductionMode> all = modes();
  if (std::find(all.begin(), all.end(), ReductionMode::Private) == all.end())
    GTEST_SKIP() << "the device cannot run the private-histogram backward pass";
  Scene s = make_scene({8, 8, 8}, 9, 20, 150);
  const ImageLossGradient one_group = gpu(ctx(), s, 0, ReductionMode::Private);
  EXPECT_TRUE(same_bits(one_group, gpu(ctx(), s, 0, ReductionMode::Private)));
  EXPECT_TRUE(same_bits(one_group, gpu(ctx(), s, 0, ReductionMode::Private, 1)));
  // Every lane marches 4 rows 16 apart: the last workgroup's rows stop at the image (150 rows,
  // not a multiple of 64) and each pixel is counted once, as the CPU reference shows.
  compare(s);
}

}  // namespace
}  // namespace tfm
