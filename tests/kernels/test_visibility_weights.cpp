// Visibility-weighted least squares: the weight pass against its double-precision CPU reference
// on awkward grids and several cameras, the weighted assembly against the exact fixed-point
// emulation, and the weighted system's solution against a dense weighted least-squares solve
// of the explicit matrix.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "test_data.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/render_image.h"
#include "tfmatch/kernels/visibility_weights.h"
#include "tfmatch/model/cameras.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/reference/visibility_weights_cpu.h"
#include "tfmatch/solvers/normal_equations.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using VisibilityWeightsTest = test::GpuTest;

struct WeightCase {
  std::string name;
  std::array<uint64_t, 3> dims;
  std::array<double, 3> spacing;
  uint64_t max_chunk;  // 0: one chunk
  std::vector<OrbitCamera> cameras;
};

// A field with blobs of high opacity (so voxels behind them are hidden), a NaN slab, values
// outside the range.
Volume blob_field(const std::array<uint64_t, 3>& dims, const std::array<double, 3>& spacing) {
  return test::make_volume(dims, spacing, "blobs", [&](uint64_t x, uint64_t y, uint64_t z, uint64_t) {
    if (z == 1 && x < 2) return NAN;
    const double fx = double(x) / double(dims[0]), fy = double(y) / double(dims[1]), fz = double(z) / double(dims[2]);
    return float(std::sin(5.0 * fx + 1.0) * std::cos(4.0 * fy) + 1.4 * std::exp(-20.0 * ((fx - 0.5) * (fx - 0.5) +
                                                                                        (fy - 0.4) * (fy - 0.4) +
                                                                                        (fz - 0.5) * (fz - 0.5))));
  });
}

TEST_F(VisibilityWeightsTest, MatchTheCpuReferenceOnAwkwardGridsAndCameras) {
  OrbitCamera base;
  std::vector<OrbitCamera> ring = fibonacci_cameras(5, base);
  RandomCameras random(7, base);
  std::vector<OrbitCamera> drawn = random.next(3);
  OrbitCamera top = base, near = base;
  top.elevation_deg = 90.0;  // the pole: the camera basis must not break
  near.distance = 1.3;       // close: parts of the box outside the frustum
  near.fov_deg = 25.0;
  const std::vector<WeightCase> cases = {
      {"13x9x7, one camera", {13, 9, 7}, {1, 1, 1}, 0, {base}},
      {"13x9x7 in 3 chunks, 5 Fibonacci cameras", {13, 9, 7}, {1, 1, 1}, 320, ring},
      {"6x11x5 anisotropic, random cameras, the pole, a near camera", {6, 11, 5}, {1.0, 0.7, 2.5}, 0,
       {drawn[0], drawn[1], drawn[2], top, near}},
      {"1x1x1", {1, 1, 1}, {1, 1, 1}, 0, {base, top}},
      {"17x3x2 thin, in 2 chunks", {17, 3, 2}, {1, 1, 1}, 64, ring},
  };
  const TransferFunction tf = test::random_tf(11, 3, 0.0, 1.0, 0.0, 1.0);
  const FieldRange range{-1.0, 1.6};
  RenderSettings s;
  s.width = 48;
  s.height = 40;
  s.opacity_scale = 12.0;
  for (const WeightCase& c : cases) {
    SCOPED_TRACE(c.name);
    const Volume vol = blob_field(c.dims, c.spacing);
    const DeviceField ref(ctx(), vol.values, "ref", c.max_chunk);
    const FieldMapping map = make_mapping(range, uint32_t(tf.size()));
    const Buffer tf_buffer = upload_tf(ctx(), tf, "tf");
    const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing, s.z_scale);
    VisibilityWeightsKernel kernel(ctx(), uint32_t(ref.chunk_count()));
    const VisibilityWeights gpu = kernel.compute(ref, geo, map, tf_buffer, s, c.cameras);
    const CpuVisibilityWeights cpu = visibility_weights_cpu(vol, tf, range, s, c.cameras, true);
    ASSERT_EQ(gpu.weights.chunk_voxels(), ref.chunk_voxels());
    EXPECT_NEAR(gpu.max_sum, cpu.max_sum, 1e-4 * cpu.max_sum);
    std::vector<float> w(vol.values.size());
    for (size_t k = 0; k < gpu.weights.chunk_count(); ++k)
      readback(ctx(), gpu.weights.chunk(k), w.data() + gpu.weights.chunk_begin(k), gpu.weights.chunk_size(k) * 4);
    double worst = 0.0;
    size_t seen = 0, compared = 0;
    for (size_t i = 0; i < w.size(); ++i) {
      ASSERT_GE(w[i], 0.0f);
      ASSERT_LE(w[i], 1.0f);
      EXPECT_EQ(w[i] * 65536.0f, std::round(w[i] * 65536.0f)) << "voxel " << i << ": not a multiple of 2^-16";
      // A sample on the edge of a NaN cell may be empty in float and not in double, or the reverse.
      if (!cpu.ambiguous[i]) worst = std::max(worst, std::abs(double(w[i]) - cpu.weights[i])), ++compared;
      seen += cpu.weights[i] > 0.0 ? 1 : 0;
    }
    // Quantization (2^-17) plus float marching against double.
    EXPECT_LT(worst, 1e-4) << "largest difference from the CPU reference";
    EXPECT_GT(seen, 0u);
    // The voxels left out as ambiguous are the few on the edges of NaN cells, not the comparison.
    EXPECT_GT(compared, w.size() * 9 / 10) << compared << " of " << w.size() << " compared";
  }
}

// Rays marched one view at a time in parts (as on llvmpipe beyond ~65 000 samples), forced here
// at 7 and 50 samples a part on short rays: the same samples in the same order, the float product
// kept between parts, so the same bits as whole rays, in chunks too.
TEST_F(VisibilityWeightsTest, RaysInPartsGiveTheBitsOfWholeRays) {
  OrbitCamera base;
  const std::vector<OrbitCamera> ring = fibonacci_cameras(4, base);
  const Volume vol = blob_field({13, 9, 7}, {1, 1, 1});
  const TransferFunction tf = test::random_tf(11, 3, 0.0, 1.0, 0.0, 1.0);
  const FieldMapping map = make_mapping({-1.0, 1.6}, uint32_t(tf.size()));
  RenderSettings s;
  s.width = 48;
  s.height = 40;
  s.opacity_scale = 12.0;
  s.step_voxels = 0.25;
  const DeviceField ref(ctx(), vol.values, "ref", 320);
  const Buffer tf_buffer = upload_tf(ctx(), tf, "tf");
  const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing, s.z_scale);
  ASSERT_GT(march_constants(s, geo).max_steps, 50u) << "the parts must split the rays";
  VisibilityWeightsKernel kernel(ctx(), uint32_t(ref.chunk_count()));
  auto weights = [&](uint32_t max_part) {
    const VisibilityWeights w = kernel.compute(ref, geo, map, tf_buffer, s, ring, max_part);
    std::vector<float> out(vol.values.size());
    for (size_t k = 0; k < w.weights.chunk_count(); ++k)
      readback(ctx(), w.weights.chunk(k), out.data() + w.weights.chunk_begin(k), w.weights.chunk_size(k) * 4);
    return std::pair{w.max_sum, out};
  };
  const auto [whole_max, whole] = weights(0);
  for (const uint32_t part : {7u, 50u}) {
    SCOPED_TRACE(part);
    const auto [max_sum, in_parts] = weights(part);
    EXPECT_EQ(max_sum, whole_max);
    ASSERT_EQ(in_parts.size(), whole.size());
    EXPECT_EQ(std::memcmp(in_parts.data(), whole.data(), whole.size() * sizeof(float)), 0);
  }
  size_t positive = 0;
  for (float w : whole) positive += w > 0.0f ? 1 : 0;
  EXPECT_GT(positive, whole.size() / 2);
}

void expect_nothing_in_view(const VisibilityWeightsKernel& kernel, const DeviceField& field, const Volume& vol,
                            const Buffer& tf, const RenderSettings& s, const OrbitCamera& cam) {
  const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing, 1.0);
  try {
    kernel.compute(field, geo, make_mapping({0, 1}, 2), tf, s, std::vector{cam});
    ADD_FAILURE() << "no voxel is in view: expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no voxel is in the view"), std::string::npos) << e.what();
  }
}

TEST_F(VisibilityWeightsTest, HiddenVoxelsWeighLessAndNothingInViewIsAnError) {
  // An opaque front half: seen from +x (azimuth 0), the back half is hidden.
  const std::array<uint64_t, 3> dims{16, 8, 8};
  const Volume vol = test::make_volume(dims, {1, 1, 1}, "wall", [](uint64_t x, uint64_t, uint64_t, uint64_t) {
    return x >= 8 ? 1.0f : 0.0f;
  });
  TransferFunction tf = test::random_tf(2, 1);
  tf.rgba[0][3] = 0.0;
  tf.rgba[1][3] = 1.0;
  const DeviceField ref(ctx(), vol.values, "ref");
  const Buffer tf_buffer = upload_tf(ctx(), tf, "tf");
  RenderSettings s;
  s.width = s.height = 32;
  OrbitCamera cam;
  cam.azimuth_deg = 0.0;
  cam.elevation_deg = 0.0;
  const VolumeGeometry geo = VolumeGeometry::from(vol.dims, vol.spacing, 1.0);
  VisibilityWeightsKernel kernel(ctx(), 1);
  const VisibilityWeights w = kernel.compute(ref, geo, make_mapping({0, 1}, 2), tf_buffer, s, std::vector{cam});
  std::vector<float> values(vol.values.size());
  readback(ctx(), w.weights.chunk(0), values.data(), values.size() * 4);
  double front = 0.0, back = 0.0;
  for (uint64_t i = 0; i < values.size(); ++i) (i % 16 >= 12 ? front : i % 16 < 8 ? back : front) += values[i];
  EXPECT_GT(front, 100.0 * back) << "the opaque half hides the voxels behind it";
  EXPECT_THROW(kernel.compute(ref, geo, make_mapping({0, 1}, 2), tf_buffer, s, std::vector<OrbitCamera>{}),
               std::invalid_argument);
  // A camera whose narrow view falls between the voxel centres of a 2x2x2 grid: nothing in view.
  const Volume small = test::make_volume({2, 2, 2}, {1, 1, 1}, "small", [](uint64_t, uint64_t, uint64_t, uint64_t) {
    return 0.5f;
  });
  const DeviceField small_field(ctx(), small.values, "small");
  OrbitCamera narrow = cam;
  narrow.distance = 3.0;
  narrow.fov_deg = 0.01;
  expect_nothing_in_view(kernel, small_field, small, tf_buffer, s, narrow);
}

// The weighted assembly gives exactly the fixed-point emulation's bits for any weights in [0, 1]
// (here multiples of 2^-16, as the weight pass writes them), for split fields and every path.
TEST_F(VisibilityWeightsTest, WeightedAssemblyIsExact) {
  const size_t n = 70001;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-0.1f, 1.1f);
  std::vector<float> ref(n), opt(n), weights(n);
  for (size_t i = 0; i < n; ++i) {
    ref[i] = u(rng);
    opt[i] = 2.0f * u(rng);
    weights[i] = float(rng() % 65537) / 65536.0f;
    if (i % 17 == 3) opt[i] = NAN;
    if (i % 5 == 1) weights[i] = 1.0f;
    if (i % 7 == 2) weights[i] = 0.0f;
  }
  const TransferFunction ref_tf = test::random_tf(12, 9);
  const FieldMapping rm = make_mapping({0.0, 1.0}, 12), om = make_mapping({0.0, 2.0}, 16),
                     before = make_mapping({0.0, 2.0}, 12);
  const std::vector<uint64_t> expected = assemble_normal_equations_fixed_point(ref, opt, rm, om, ref_tf, nullptr, weights);
  const std::vector<uint64_t> expected_before =
      assemble_normal_equations_fixed_point(ref, opt, rm, om, ref_tf, &before, weights);
  const std::vector<uint64_t> unweighted = assemble_normal_equations_fixed_point(ref, opt, rm, om, ref_tf);
  EXPECT_NE(expected, unweighted);
  const Buffer tf = upload_tf(ctx(), ref_tf, "tf");
  for (uint64_t chunk : {uint64_t(0), uint64_t(16384)}) {
    const DeviceField r(ctx(), ref, "ref", chunk), o(ctx(), opt, "opt", chunk), w(ctx(), weights, "weights", chunk);
    for (ReductionMode mode : {ReductionMode::RunsShared, ReductionMode::RunsGlobal, ReductionMode::Private}) {
      ReductionOptions options;
      options.mode = mode;
      options.range_quads = 2048;
      SCOPED_TRACE("chunk " + std::to_string(chunk) + ", mode " + std::to_string(int(mode)));
      GpuNormalEquations gpu(ctx(), 16, options);
      gpu.add(r, o, rm, om, tf, nullptr, &w);
      EXPECT_EQ(gpu.fixed_point_slots(), expected);
      GpuNormalEquations with_before(ctx(), 16, options);
      with_before.add(r, o, rm, om, tf, &before, &w);
      EXPECT_EQ(with_before.fixed_point_slots(), expected_before);
    }
  }
  // Weights of another chunking are refused.
  const DeviceField r(ctx(), ref, "ref", 16384), o(ctx(), opt, "opt", 16384), w(ctx(), weights, "weights");
  GpuNormalEquations gpu(ctx(), 16);
  EXPECT_THROW(gpu.add(r, o, rm, om, tf, nullptr, &w), std::invalid_argument);
}

// The weighted system's solution is the weighted least-squares solution of the explicit A:
// minimize sum_i w_i ||a_i x - b_i||^2, a_i the TF interpolation row of voxel i, solved dense.
TEST_F(VisibilityWeightsTest, WeightedSystemSolvesTheDenseWeightedLeastSquares) {
  const size_t n = 3001;
  const uint32_t entries = 9;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> ref(n), opt(n), weights(n);
  for (size_t i = 0; i < n; ++i) {
    ref[i] = u(rng);
    opt[i] = std::pow(ref[i], 1.7f) + 0.05f * u(rng);
    weights[i] = float(rng() % 65537) / 65536.0f;
  }
  const TransferFunction ref_tf = test::random_tf(7, 4);
  const FieldMapping rm = make_mapping({0.0, 1.0}, 7), om = make_mapping({0.0, 1.1}, entries);
  const DeviceField r(ctx(), ref, "ref"), o(ctx(), opt, "opt"), w(ctx(), weights, "weights");
  const Buffer tf = upload_tf(ctx(), ref_tf, "tf");
  GpuNormalEquations gpu(ctx(), entries);
  gpu.add(r, o, rm, om, tf, nullptr, &w);
  const SolveResult solved = solve_normal_equations(gpu.result());

  // The explicit rows, in double, at the kernel's float32 TF coordinates.
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(Eigen::Index(n), entries);
  Eigen::MatrixXd b(Eigen::Index(n), 4);
  Eigen::VectorXd sw(static_cast<Eigen::Index>(n));
  const std::vector<float> table = ref_tf.as_floats();
  for (size_t i = 0; i < n; ++i) {
    uint32_t jr, jo;
    float wr, wo;
    ASSERT_TRUE(tf_coordinate(ref[i], rm, jr, wr) && tf_coordinate(opt[i], om, jo, wo));
    a(Eigen::Index(i), jo) = 1.0 - wo;
    a(Eigen::Index(i), jo + 1) += wo;
    for (int c = 0; c < 4; ++c)
      b(Eigen::Index(i), c) = std::clamp((1.0 - wr) * table[4 * jr + c] + double(wr) * table[4 * (jr + 1) + c], 0.0, 1.0);
    sw(Eigen::Index(i)) = std::sqrt(double(weights[i]));
  }
  const Eigen::MatrixXd x = (sw.asDiagonal() * a).colPivHouseholderQr().solve(sw.asDiagonal() * b);
  // The unweighted solution differs: the weights matter.
  const Eigen::MatrixXd x_plain = a.colPivHouseholderQr().solve(b);
  double diff = 0.0, plain_diff = 0.0;
  for (Eigen::Index j = 0; j < x.rows(); ++j)
    for (int c = 0; c < 4; ++c) {
      diff = std::max(diff, std::abs(solved.x(j, c) - x(j, c)));
      plain_diff = std::max(plain_diff, std::abs(x_plain(j, c) - x(j, c)));
    }
  EXPECT_LT(diff, 1e-5);
  EXPECT_GT(plain_diff, 1e-3);
}

}  // namespace
}  // namespace tfm
