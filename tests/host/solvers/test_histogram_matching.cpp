// The histogram-matching solver: its CDF and quantile functions on closed forms; the solver
// against an independent quantile mapping by sorting (exact empirical distributions, no
// histogram); and the paper's counter-example, a ramp against its reversed copy, where histogram
// matching keeps a large residual and least squares reaches zero.
#include <algorithm>
#include <cmath>
#include <vector>

#include "solver_problem.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/reference/histogram_cpu.h"
#include "tfmatch/solvers/histogram_matching.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

// T(u) with the kernels' float mapping, interpolated in double, clamped.
Rgba classify(const TransferFunction& tf, const FieldMapping& m, double u) {
  uint32_t j;
  float w;
  tf_coordinate(float(u), m, j, w);
  Rgba out;
  for (int c = 0; c < 4; ++c) out[c] = std::clamp((1.0 - w) * tf.rgba[j][c] + double(w) * tf.rgba[j + 1][c], 0.0, 1.0);
  return out;
}

// T_r(F_r^-1(F_o(v))) from the sorted finite values: F_o(v) = #{o <= v} / n_o, F_r^-1(q) = the
// smallest reference value x with #{r <= x} / n_r >= q.
TransferFunction quantile_mapping_by_sorting(std::vector<float> ref, std::vector<float> opt,
                                             const TransferFunction& ref_tf, const FieldMapping& rm,
                                             const FieldMapping& om) {
  std::erase_if(ref, [](float v) { return std::isnan(v); });
  std::erase_if(opt, [](float v) { return std::isnan(v); });
  std::sort(ref.begin(), ref.end());
  std::sort(opt.begin(), opt.end());
  TransferFunction tf;
  tf.rgba.resize(om.tf_size);
  for (uint32_t j = 0; j < om.tf_size; ++j) {
    const double v = double(om.lo) + double(j) / double(om.scale);
    const double q = double(std::upper_bound(opt.begin(), opt.end(), v) - opt.begin()) / double(opt.size());
    const size_t rank = size_t(std::max(0.0, std::ceil(q * double(ref.size())) - 1.0));
    tf.rgba[j] = classify(ref_tf, rm, ref[std::min(rank, ref.size() - 1)]);
  }
  return tf;
}

double voxel_rmse(Context& ctx, test::SolverProblem& p, const TransferFunction& tf) {
  Buffer opt_tf = upload_tf(ctx, tf.as_floats(), "candidate tf");
  return voxel_loss_gpu(ctx, *p.ref, *p.opt, p.ref_map, p.opt_map, *p.ref_tf_buffer, opt_tf).rmse();
}

TEST(HistogramMatchingMath, CdfAndQuantileOfAKnownHistogram) {
  FieldHistogram h;
  h.lo = 2.0;
  h.hi = 6.0;
  h.bins = {1, 0, 2, 1};  // bins of width 1; below 1, above 1: n = 6
  h.below = 1;
  h.above = 1;
  EXPECT_DOUBLE_EQ(histogram_cdf(h, 2.0), 1.0 / 6);
  EXPECT_DOUBLE_EQ(histogram_cdf(h, 3.0), 2.0 / 6);
  EXPECT_DOUBLE_EQ(histogram_cdf(h, 4.0), 2.0 / 6);  // the empty bin is flat
  EXPECT_DOUBLE_EQ(histogram_cdf(h, 4.5), 3.0 / 6);
  EXPECT_DOUBLE_EQ(histogram_cdf(h, 6.0), 5.0 / 6);
  EXPECT_DOUBLE_EQ(histogram_quantile(h, 0.1), 2.0);  // within the mass below: lo
  EXPECT_DOUBLE_EQ(histogram_quantile(h, 1.5 / 6), 2.5);
  EXPECT_DOUBLE_EQ(histogram_quantile(h, 2.0 / 6), 3.0);  // smallest value reaching it: not 4
  EXPECT_DOUBLE_EQ(histogram_quantile(h, 3.0 / 6), 4.5);
  EXPECT_DOUBLE_EQ(histogram_quantile(h, 0.9), 6.0);  // within the mass above: hi
  for (double v : {2.2, 3.0, 4.1, 5.7}) EXPECT_NEAR(histogram_quantile(h, histogram_cdf(h, v)), v, 1e-12) << v;
  EXPECT_THROW(histogram_cdf(FieldHistogram{0.0, 1.0, {0, 0}}, 0.5), std::invalid_argument);
}

class HistogramMatching : public test::GpuTest {};

TEST_F(HistogramMatching, EqualsAnIndependentQuantileMapping) {
  // A monotone increasing remap with NaN in the second field: histogram matching recovers it.
  test::SolverProblem p = test::make_solver_problem(120001, 48, 12, 0.0, 1.0, 41, 0.0, 97);
  p.upload(ctx(), 50000);  // three chunks
  SolverSettings settings;
  settings.extra["histogram-bins"] = "65536";
  const SolverOutput out = p.solve(ctx(), "histogram-matching", settings);
  const TransferFunction expect =
      quantile_mapping_by_sorting(p.ref_volume.values, p.opt_volume.values, p.ref_tf, p.ref_map, p.opt_map);
  // The histogram's quantiles are within a bin (1.5e-5 of the range) and the sorted ones within
  // one sample (~1e-5) of the true ones; the reference TF changes by at most 1 per 1/11 of the
  // range: 2e-3 bounds the difference with margin.
  EXPECT_LT(test::max_difference(out.tf, expect), 2e-3);
  EXPECT_EQ(out.details["histogram_bins"].get<uint64_t>(), 65536u);
  // Where the relation is monotone increasing, matching quantiles is nearly the least-squares
  // optimum.
  const SolverOutput ls = p.solve(ctx(), "normal-equations");
  EXPECT_LT(voxel_rmse(ctx(), p, out.tf), voxel_rmse(ctx(), p, ls.tf) + 0.01);
}

TEST_F(HistogramMatching, LosesToLeastSquaresOnAReversedRamp) {
  // Reference: a ramp 0..1 along x on 64x64; field: the same ramp reversed, 1 - v. The two have
  // one distribution, so histogram matching returns the reference TF itself; least squares finds
  // T_o(v) = T_r(1 - v) (nodes aligned: exact).
  test::SolverProblem p;
  p.ref_volume.dims = p.opt_volume.dims = {64, 64, 1};
  for (uint32_t y = 0; y < 64; ++y)
    for (uint32_t x = 0; x < 64; ++x) {
      const float v = float(x) / 63.0f;
      p.ref_volume.values.push_back(v);
      p.opt_volume.values.push_back(1.0f - v);
    }
  p.ref_tf.rgba.resize(32);
  for (uint32_t j = 0; j < 32; ++j) {
    const double t = j / 31.0;
    p.ref_tf.rgba[j] = {t, 0.3, 1.0 - t, 0.1 + 0.8 * t * t};
  }
  p.ref_map = make_mapping({0.0, 1.0}, 32);
  p.opt_map = make_mapping({0.0, 1.0}, 32);
  p.upload(ctx());
  const SolverOutput hm = p.solve(ctx(), "histogram-matching");
  const SolverOutput ls = p.solve(ctx(), "normal-equations");
  // The reference TF, up to the quantization of the data: 64 levels 1/63 apart, each spread over
  // its bin by the histogram, so a quantile lands within a level step of the exact one; the TF's
  // steepest channel (opacity, slope 1.6) then moves by < 1.6 / 63 = 0.025.
  EXPECT_LT(test::max_difference(hm.tf, p.ref_tf), 0.026);
  const double hm_rmse = voxel_rmse(ctx(), p, hm.tf), ls_rmse = voxel_rmse(ctx(), p, ls.tf);
  EXPECT_GT(hm_rmse, 0.3);
  EXPECT_LT(ls_rmse, 1e-3);
}

}  // namespace
}  // namespace tfm
