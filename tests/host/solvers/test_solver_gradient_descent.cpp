// Gradient descent on the GPU: the gradient kernel against a double CPU reference (l2 and l1,
// awkward sizes, NaNs, both accumulation paths), the update kernel's Adam and SGD steps against
// hand-computed ones, two whole iterations against a CPU replay, convergence to the exact QP
// solution (l2) and to the per-entry weighted median (l1, closed form), determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "solver_problem.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/gradient_descent.h"
#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/solvers/box_qp.h"
#include "tfmatch/solvers/solver_gradient_descent.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

class SolverGradientDescent : public test::GpuTest {};

TEST_F(SolverGradientDescent, GradientKernelMatchesCpu) {
  const uint32_t n = 9;
  std::vector<ReductionOptions> paths;
  for (ReductionMode mode : {ReductionMode::RunsShared, ReductionMode::RunsGlobal, ReductionMode::Private})
    for (AtomicWidth width : {AtomicWidth::Bits32, AtomicWidth::Bits64})
      // Private histograms are a 64-bit path only.
      if (width == AtomicWidth::Bits64 ? ctx().int64_atomics() : mode != ReductionMode::Private)
        paths.push_back({mode, width});
  for (bool l1 : {false, true})
    for (const ReductionOptions& path : paths) {
      const GdGradientKernel kernel(ctx(), n, l1, path);
      for (size_t voxels : {size_t(1), size_t(13), size_t(127), size_t(TFM_VOXEL_WORKGROUP + 1), size_t(5000)}) {
        SCOPED_TRACE(std::string(l1 ? "l1 " : "l2 ") + reduction_mode_name(path.mode) +
                     (path.atomics == AtomicWidth::Bits64 ? " 64-bit " : " 32-bit ") + std::to_string(voxels));
        test::SolverProblem p = test::make_solver_problem(voxels, n, 7, 0.0, 1.0, 11, 0.3, 7);
        p.ref_volume.values[0] = voxels > 1 ? NAN : p.ref_volume.values[0];
        p.upload(ctx(), voxels > 1000 ? 2048 : 0);
        std::mt19937 rng(3);
        std::uniform_real_distribution<float> u(0.0f, 1.0f);
        std::vector<float> x(4 * n);
        for (float& v : x) v = u(rng);
        Buffer xb = make_buffer<float>(ctx(), x, "x");
        Buffer accum(ctx(), gd_accumulator_bytes(n), MemoryUsage::Device, "accum");
        CommandBatch batch(ctx());
        batch.fill(accum, 0u);
        batch.barrier();
        kernel.record(batch, *p.ref, *p.opt, p.ref_map, p.opt_map, *p.ref_tf_buffer, xb, accum);
        batch.submit_and_wait();
        std::vector<uint32_t> words(gd_accumulator_bytes(n) / 4);
        readback(ctx(), accum, words.data(), words.size() * 4);
        const auto loss_words = words.begin() + TFM_FIXED_SLOT_WORDS * TFM_GD_LOSS_SLOT(n);
        const std::vector<double> grad = decode_signed_fixed_point(std::vector<uint32_t>(words.begin(), loss_words));
        const std::vector<double> loss = decode_fixed_point(std::vector<uint32_t>(loss_words, words.end()));

        std::vector<double> expected(4 * n, 0.0), tol(4 * n, 1e-12);
        double expected_loss[4] = {0, 0, 0, 0}, loss_tol = double(voxels) * std::ldexp(1.0, -32) + 1e-12;
        for (size_t i = 0; i < voxels; ++i) {
          uint32_t j;
          float w;
          double b[4];
          if (!p.voxel_terms(i, j, w, b)) continue;
          for (int c = 0; c < 4; ++c) {
            const double e = (1.0 - w) * x[4 * j + c] + double(w) * x[4 * (j + 1) + c] - b[c];
            // The kernel forms e in float: within 1e-6 of this for values in [0,1]. For l1 a sign
            // can flip only when |e| < 1e-6; such a voxel may move the sum by its full weight.
            const double d = l1 ? (e > 0 ? 1.0 : (e < 0 ? -1.0 : 0.0)) : e;
            const double flip = l1 ? (std::abs(e) < 1e-6 ? 2.0 : 0.0) : 1e-6;
            expected[4 * j + c] += (1.0 - w) * d;
            expected[4 * (j + 1) + c] += double(w) * d;
            // Each term a float product (2^-24 relative; 2^-22 with the roundings of w and
            // 1 - w) truncated to 2^-32 on its own.
            tol[4 * j + c] += (1.0 - w) * (std::abs(d) * std::ldexp(1.0, -22) + flip) + std::ldexp(1.0, -32);
            tol[4 * (j + 1) + c] += double(w) * (std::abs(d) * std::ldexp(1.0, -22) + flip) + std::ldexp(1.0, -32);
            expected_loss[c] += l1 ? std::abs(e) : e * e;
            loss_tol += 3e-6;  // e within 1e-6, |e| <= 1: e^2 within 2e-6 plus rounding
          }
        }
        for (size_t k = 0; k < expected.size(); ++k)
          ASSERT_NEAR(grad[k], expected[k], tol[k]) << "slot " << k << " (entry " << k / 4 << ", channel " << k % 4 << ")";
        for (int c = 0; c < 4; ++c) ASSERT_NEAR(loss[c], expected_loss[c], loss_tol) << "loss channel " << c;
      }
    }
}

// Signed 32.32 accumulator words for the given sums (exact for multiples of 2^-20 here).
std::vector<uint32_t> encode_signed(const std::vector<double>& sums) {
  std::vector<uint32_t> words(TFM_GD_ACCUM_WORDS(sums.size() / 4), 0u);
  for (size_t k = 0; k < sums.size(); ++k) {
    const uint64_t v = uint64_t(std::llround(sums[k] * 4294967296.0));  // two's complement
    words[2 * k] = uint32_t(v);
    words[2 * k + 1] = uint32_t(v >> 32);
  }
  return words;
}

TEST_F(SolverGradientDescent, UpdateKernelTakesHandComputedAdamAndSgdSteps) {
  const uint32_t n = TFM_VECTOR_WORKGROUP + 44;  // more entries than invocations: two blocks
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<double> sums(4 * n);
  for (double& s : sums) s = std::ldexp(std::round((u(rng) - 0.5) * 4096.0), -10);  // exact in fixed point
  std::vector<float> x(4 * n), m(4 * n), v(4 * n), inv_diag(n);
  for (auto& e : x) e = float(u(rng));
  for (auto& e : m) e = float((u(rng) - 0.5) * 1e-3);
  for (auto& e : v) e = float(u(rng) * 1e-6);
  for (auto& e : inv_diag) e = float(1.0 / (1.0 + 100.0 * u(rng)));
  for (bool adam : {true, false}) {
    SCOPED_TRACE(adam ? "adam" : "sgd");
    Buffer accum = make_buffer<uint32_t>(ctx(), encode_signed(sums), "accum");
    Buffer xb = make_buffer<float>(ctx(), x, "x"), mb = make_buffer<float>(ctx(), m, "m");
    Buffer vb = make_buffer<float>(ctx(), v, "v"), db = make_buffer<float>(ctx(), inv_diag, "inv diag");
    Buffer gb(ctx(), uint64_t(n) * 16, MemoryUsage::Device, "gradient");
    gpu::GdUpdatePush push{};
    push.tf_size = n;
    push.optimizer = adam ? TFM_GD_OPTIMIZER_ADAM : TFM_GD_OPTIMIZER_SGD;
    push.data_scale = 1e-4f;
    push.reg_scale = 2e-4f;
    push.ridge_weight = 3.0f;
    push.smooth_weight = 5.0f;
    push.lr = 0.01f;
    push.beta1 = 0.9f;
    push.beta2 = 0.999f;
    push.bias1 = float(1.0 / (1.0 - std::pow(0.9, 3.0)));  // step t = 3
    push.bias2 = float(1.0 / (1.0 - std::pow(0.999, 3.0)));
    push.epsilon = 1e-8f;
    GdUpdateKernel kernel(ctx());
    CommandBatch batch(ctx());
    kernel.record(batch, push, {&accum, &xb, &mb, &vb, &db, &gb});
    batch.submit_and_wait();
    std::vector<float> x2(4 * n), m2(4 * n), v2(4 * n), g2(4 * n);
    readback(ctx(), xb, x2.data(), x2.size() * 4);
    readback(ctx(), mb, m2.data(), m2.size() * 4);
    readback(ctx(), vb, v2.data(), v2.size() * 4);
    readback(ctx(), gb, g2.data(), g2.size() * 4);
    for (uint32_t j = 0; j < n; ++j)
      for (int c = 0; c < 4; ++c) {
        const size_t k = 4 * j + c;
        double dtd = 0.0;
        if (j > 0) dtd += double(x[k]) - x[k - 4];
        if (j + 1 < n) dtd += double(x[k]) - x[k + 4];
        const double g = 1e-4 * sums[k] + 2e-4 * (3.0 * x[k] + 5.0 * dtd);
        // g is a few float operations: within 1e-6 of the magnitudes of its terms (which may
        // cancel), |x| <= 1 and |D^T D x| <= 2 bound the penalty terms.
        const double g_tol = 1e-6 * (1e-4 * std::abs(sums[k]) + 2e-4 * (3.0 + 5.0 * 2.0)) + 1e-12;
        ASSERT_NEAR(g2[k], g, g_tol) << "gradient " << k;
        // The kernel's constants are the floats of the push block (1 - beta2 is exact in float
        // but differs from 0.001 by 1e-5 relative): the hand computation uses the same values.
        const double b1 = push.beta1, b2 = push.beta2, lr = push.lr;
        double step;
        if (adam) {
          const double mk = b1 * m[k] + (1.0 - b1) * g, vk = b2 * v[k] + (1.0 - b2) * g * g;
          // Relative to the terms, which may cancel; g carries g_tol.
          ASSERT_NEAR(m2[k], mk, 1e-6 * (b1 * std::abs(m[k]) + (1.0 - b1) * std::abs(g)) + g_tol) << "m " << k;
          ASSERT_NEAR(v2[k], vk, 1e-6 * vk + 0.002 * std::abs(g) * g_tol + 1e-20) << "v " << k;
          step = lr * (mk * double(push.bias1)) / (std::sqrt(vk * double(push.bias2)) + double(push.epsilon));
        } else {
          step = lr * g * inv_diag[j] / double(push.reg_scale);
        }
        // x in [0,1] after a float step: a few ulps of the step and of x, < 1e-6.
        ASSERT_NEAR(x2[k], std::clamp(x[k] - step, 0.0, 1.0), 1e-6) << "x " << k;
      }
  }
}

TEST_F(SolverGradientDescent, TwoIterationsMatchACpuReplay) {
  test::SolverProblem p = test::make_solver_problem(13, 4, 5, 0.0, 1.0, 21);
  p.upload(ctx());
  SolverSettings s;
  s.extra["iterations"] = "2";
  s.extra["lr"] = "0.1";
  const SolverOutput out = p.solve(ctx(), "gradient-descent", s);
  // Replay in double: x0 = 0, gradient of mean squared error over voxels and RGBA, Adam with the
  // solver's schedule (gd_learning_rate) and bias corrections, projection to [0,1].
  GradientDescentOptions o;  // as the solver reads the options above
  o.iterations = 2;
  o.lr = 0.1;
  const uint32_t n = 4;
  std::vector<double> x(4 * n, 0.0), m(4 * n, 0.0), v(4 * n, 0.0);
  size_t voxels = 0;
  for (size_t i = 0; i < 13; ++i) {
    uint32_t j;
    float w;
    double b[4];
    voxels += p.voxel_terms(i, j, w, b) ? 1 : 0;
  }
  for (uint32_t t = 1; t <= 2; ++t) {
    std::vector<double> g(4 * n, 0.0);
    for (size_t i = 0; i < 13; ++i) {
      uint32_t j;
      float w;
      double b[4];
      if (!p.voxel_terms(i, j, w, b)) continue;
      for (int c = 0; c < 4; ++c) {
        const double e = (1.0 - w) * x[4 * j + c] + double(w) * x[4 * (j + 1) + c] - b[c];
        g[4 * j + c] += 2.0 / (4.0 * voxels) * (1.0 - w) * e;
        g[4 * (j + 1) + c] += 2.0 / (4.0 * voxels) * double(w) * e;
      }
    }
    const double lr = gd_learning_rate(o, t);
    for (size_t k = 0; k < x.size(); ++k) {
      m[k] = 0.9 * m[k] + 0.1 * g[k];
      v[k] = 0.999 * v[k] + 0.001 * g[k] * g[k];
      const double mh = m[k] / (1.0 - std::pow(0.9, t)), vh = v[k] / (1.0 - std::pow(0.999, t));
      x[k] = std::clamp(x[k] - lr * mh / (std::sqrt(vh) + 1e-8), 0.0, 1.0);
    }
  }
  double worst = 0.0;
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) worst = std::max(worst, std::abs(out.tf.rgba[j][c] - x[4 * j + c]));
  // Float arithmetic on values <= 1 over two steps: ~1e-6; Adam's first steps are ~lr in size,
  // so a wrong moment, bias correction or schedule would be off by > 1e-3.
  EXPECT_LT(worst, 1e-5);
}

TEST_F(SolverGradientDescent, L2ConvergesToTheBoxConstrainedOptimum) {
  // Sharp reference TF (0/1 entries): the unconstrained fit leaves [0,1], so the projected
  // iteration must find the QP solution, not the clamped one.
  test::SolverProblem p = test::make_solver_problem(4000, 12, 24, 0.0, 1.0, 31);
  for (auto& e : p.ref_tf.rgba)
    for (double& c : e) c = c > 0.5 ? 1.0 : 0.0;
  p.upload(ctx());
  const NormalEquations eq = p.cpu_equations();
  const SolveResult clamped = solve_normal_equations(eq);
  ASSERT_GT(clamped.clamped_values, 0u);
  const BoxQpResult qp = solve_box_constrained(eq);
  ASSERT_GT(test::max_difference(clamped.tf, qp.tf), 1e-2) << "clamping should not reach the optimum here";
  SolverSettings s;
  s.extra["iterations"] = "400";
  const SolverOutput out = p.solve(ctx(), "gradient-descent", s);
  EXPECT_TRUE(test::all_finite_in_box(out.tf));
  // Adam ends with steps of lr/100 = 2e-4 and settles well inside them (measured: 6e-6 on
  // lavapipe); Jacobi-scaled SGD converges linearly (measured: 4e-8). 1e-4 leaves margin and is
  // 100 times below the error of clamping.
  EXPECT_LT(test::max_difference(out.tf, qp.tf), 1e-4);
  // The solver's own distance to the optimum is this one (its system comes from the GPU's
  // fixed-point assembly, the same numbers to rounding), and so close it says nothing.
  EXPECT_NEAR(out.details["distance_to_optimum"].get<double>(), test::max_difference(out.tf, qp.tf), 1e-7);
  EXPECT_TRUE(out.warnings.empty()) << out.warnings.front();
  s.extra["optimizer"] = "sgd";
  const SolverOutput sgd = p.solve(ctx(), "gradient-descent", s);
  EXPECT_LT(test::max_difference(sgd.tf, qp.tf), 1e-4);
}

// Heavy smoothing makes the problem stiff for a fixed number of gradient steps (Adam's steps are
// about lr in size whatever the curvature; SGD's are scaled by the diagonal only): the iterate
// ends far from the optimum, and the solver measures how far and warns instead of returning it
// silently. The l1 loss has no exact minimizer at hand and reports none.
TEST_F(SolverGradientDescent, EndingFarFromTheOptimumIsMeasuredAndWarned) {
  test::SolverProblem p = test::make_solver_problem(4000, 12, 24, 0.0, 1.0, 31);
  p.upload(ctx());
  const NormalEquations eq = p.cpu_equations();
  SolverSettings s;
  s.solve.smooth = 1e6;
  s.extra["iterations"] = "40";
  const BoxQpResult qp = solve_box_constrained(eq, s.solve);
  for (const char* optimizer : {"adam", "sgd"}) {
    s.extra["optimizer"] = optimizer;
    const SolverOutput out = p.solve(ctx(), "gradient-descent", s);
    const double distance = test::max_difference(out.tf, qp.tf);
    ASSERT_GT(distance, 0.05) << optimizer << ": the test needs a run that ends far away";
    EXPECT_NEAR(out.details["distance_to_optimum"].get<double>(), distance, 1e-6) << optimizer;
    ASSERT_EQ(out.warnings.size(), 1u) << optimizer;
    for (const char* word : {"--iterations 40", "--smooth", "qp"})
      EXPECT_NE(out.warnings[0].find(word), std::string::npos) << out.warnings[0];
  }
  s.extra["loss"] = "l1";
  const SolverOutput l1 = p.solve(ctx(), "gradient-descent", s);
  EXPECT_FALSE(l1.details.contains("distance_to_optimum"));
}

TEST_F(SolverGradientDescent, L1ConvergesToPerEntryWeightedMedian) {
  // Every voxel sits exactly on a TF node (integer field values on the range [0, N-1]), so the
  // l1 problem splits per entry: x_j = weighted median of the b of the voxels at node j (weight
  // = number of voxels with that b).
  const uint32_t n = 6;
  test::SolverProblem p;
  p.ref_tf.rgba = {{0.0, 1.0, 0.2, 0.1}, {1.0, 0.0, 0.8, 0.9}};  // b = (1-t) e0 + t e1, t = ref value
  p.ref_map = make_mapping({0.0, 1.0}, 2);
  p.opt_map = make_mapping({0.0, double(n - 1)}, n);
  std::mt19937 rng(7);
  std::vector<std::vector<double>> ts(n);
  for (uint32_t j = 0; j < n; ++j) {
    // Values on a grid of 1/20 (repeats act as weights), an odd total so the median is unique.
    const int distinct = 3 + int(j % 2);
    int count = 0;
    for (int k = 0; k < distinct; ++k) {
      const double t = double(rng() % 20) / 20.0 + 0.025;
      const int repeat = 1 + int(rng() % 3);
      for (int r = 0; r < repeat; ++r) ts[j].push_back(t), ++count;
    }
    if (count % 2 == 0) ts[j].push_back(ts[j].front());
    for (double t : ts[j]) {
      p.ref_volume.values.push_back(float(t));
      p.opt_volume.values.push_back(float(j));
    }
  }
  p.ref_volume.dims = p.opt_volume.dims = {p.ref_volume.values.size(), 1, 1};
  p.upload(ctx());
  SolverSettings s;
  s.extra["loss"] = "l1";
  s.extra["iterations"] = "500";
  const SolverOutput out = p.solve(ctx(), "gradient-descent", s);
  for (uint32_t j = 0; j < n; ++j) {
    std::vector<double> t = ts[j];
    std::sort(t.begin(), t.end());
    const double median_t = float(t[t.size() / 2]);
    for (int c = 0; c < 4; ++c) {
      const double b = std::clamp((1.0 - median_t) * float(p.ref_tf.rgba[0][c]) + median_t * float(p.ref_tf.rgba[1][c]), 0.0, 1.0);
      // The subgradient iteration settles within about its final step (lr/100 = 2e-4) of the
      // median (measured: <= 1.4e-4); neighbouring b values are >= 0.05 |e1 - e0| >= 0.03
      // away (|e1 - e0| >= 0.6 per channel), so 1e-3 pins the median.
      EXPECT_NEAR(out.tf.rgba[j][c], b, 1e-3) << "entry " << j << " channel " << c;
    }
  }
}

TEST_F(SolverGradientDescent, IsBitIdenticalAcrossRunsAndRejectsBadFlags) {
  test::SolverProblem p = test::make_solver_problem(20000, 32, 16, 0.0, 1.0, 41, 0.1, 13);
  p.upload(ctx());
  SolverSettings s;
  s.extra["iterations"] = "20";
  const SolverOutput a = p.solve(ctx(), "gradient-descent", s);
  const SolverOutput b = p.solve(ctx(), "gradient-descent", s);
  EXPECT_EQ(a.tf.rgba, b.tf.rgba);
  for (const auto& [flag, value] : {std::pair{"loss", "l3"}, {"optimizer", "lbfgs"}, {"lr", "-1"}, {"iterations", "0"},
                                    {"iterations", "2.5"}}) {
    SolverSettings bad = s;
    bad.extra[flag] = value;
    EXPECT_THROW(p.solve(ctx(), "gradient-descent", bad), std::runtime_error) << flag << "=" << value;
  }
}

}  // namespace
}  // namespace tfm
