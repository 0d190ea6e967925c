// Iteratively reweighted least squares on the GPU: the pass the same bits on every accumulation path
// and chunking (its cases against the double CPU reference irls_cpu.h, on awkward sizes with NaNs and
// every path, are the selftest's, run by tests/kernels/test_kernel_cases.cpp), the solver against
// the exact l1 minimum found by enumerating the vertices of a small linear program, against
// gradient descent's l1 objective on a larger problem, and its determinism and option checks.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include <Eigen/Dense>

#include "solver_problem.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/irls.h"
#include "tfmatch/solvers/box_qp.h"
#include "tfmatch/solvers/solver_irls.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

class SolverIrls : public test::GpuTest {};

TEST_F(SolverIrls, PassIsTheSameBitsOnEveryPathAndChunking) {
  const uint32_t n = 40;
  test::SolverProblem p = test::make_solver_problem(30001, n, 16, 0.0, 1.0, 5, 0.2, 97);
  std::vector<float> state(4 * (n + 1));
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (float& v : state) v = u(rng);
  for (int c = 0; c < 4; ++c) state[4 * n + c] = 1e-3f;
  Buffer sb = make_buffer<float>(ctx(), state, "state");
  std::vector<uint32_t> first;
  for (uint64_t chunk : {uint64_t(0), uint64_t(4096)}) {
    p.upload(ctx(), chunk);
    for (ReductionMode mode : {ReductionMode::Auto, ReductionMode::RunsShared, ReductionMode::RunsGlobal}) {
      for (uint32_t groups : {0u, 3u}) {
        if (groups && mode != ReductionMode::Auto) continue;  // compiles (above) are what this test costs
        const IrlsKernel kernel(ctx(), n, {mode, AtomicWidth::Auto, groups});
        Buffer accum(ctx(), irls_accumulator_bytes(n), MemoryUsage::Device, "accum");
        CommandBatch batch(ctx());
        batch.fill(accum, 0u);
        batch.barrier();
        kernel.record(batch, *p.ref, *p.opt, p.ref_map, p.opt_map, *p.ref_tf_buffer, sb, accum);
        batch.submit_and_wait();
        std::vector<uint32_t> words(irls_accumulator_bytes(n) / 4);
        readback(ctx(), accum, words.data(), words.size() * 4);
        if (first.empty()) first = words;
        EXPECT_EQ(words, first) << reduction_mode_name(mode) << ", chunk " << chunk << ", groups " << groups;
      }
    }
  }
}

// sum_i,c |e_ic| in double at the TF `x` (what the solvers minimize without regularization).
double l1_objective(const test::SolverProblem& p, const TransferFunction& x) {
  double total = 0.0;
  for (size_t i = 0; i < p.ref_volume.values.size(); ++i) {
    uint32_t j;
    float t;
    double b[4];
    if (!p.voxel_terms(i, j, t, b)) continue;
    for (int c = 0; c < 4; ++c) total += std::abs((1.0 - t) * x.rgba[j][c] + double(t) * x.rgba[j + 1][c] - b[c]);
  }
  return total;
}

// The exact minimum of sum_i |a_i x - b_i| over 0 <= x <= 1 (x in R^3) for one channel: a linear
// program, so a minimizer lies at a vertex where three independent constraints of the set
// {a_i x = b_i} and {x_j = 0}, {x_j = 1} hold; every triple is tried.
double exact_l1_minimum(const std::vector<Eigen::Vector3d>& a, const std::vector<double>& b) {
  std::vector<std::pair<Eigen::Vector3d, double>> planes;
  for (size_t i = 0; i < a.size(); ++i) planes.push_back({a[i], b[i]});
  for (int j = 0; j < 3; ++j)
    for (double bound : {0.0, 1.0}) planes.push_back({Eigen::Vector3d::Unit(j), bound});
  double best = std::numeric_limits<double>::infinity();
  for (size_t p = 0; p < planes.size(); ++p)
    for (size_t q = p + 1; q < planes.size(); ++q)
      for (size_t r = q + 1; r < planes.size(); ++r) {
        Eigen::Matrix3d m;
        m << planes[p].first.transpose(), planes[q].first.transpose(), planes[r].first.transpose();
        if (std::abs(m.determinant()) < 1e-9) continue;
        const Eigen::Vector3d x = m.partialPivLu().solve(Eigen::Vector3d(planes[p].second, planes[q].second, planes[r].second));
        if ((x.array() < -1e-12).any() || (x.array() > 1.0 + 1e-12).any()) continue;
        double f = 0.0;
        for (size_t i = 0; i < a.size(); ++i) f += std::abs(a[i].dot(x) - b[i]);
        best = std::min(best, f);
      }
  return best;
}

TEST_F(SolverIrls, ReachesTheExactL1MinimumOfASmallLinearProgram) {
  // Three TF entries, 40 voxels whose colours follow the reference TF except a quarter of them
  // (outliers with random colours): least squares is pulled by the outliers, l1 is not.
  test::SolverProblem p = test::make_solver_problem(40, 3, 5, 0.0, 1.0, 17, 0.05);
  std::mt19937 rng(23);
  for (size_t i = 0; i < 40; i += 4) p.ref_volume.values[i] = float(std::uniform_real_distribution<double>(0, 1)(rng));
  p.upload(ctx());
  std::array<std::vector<Eigen::Vector3d>, 4> a;
  std::array<std::vector<double>, 4> b;
  for (size_t i = 0; i < 40; ++i) {
    uint32_t j;
    float t;
    double bi[4];
    ASSERT_TRUE(p.voxel_terms(i, j, t, bi));
    Eigen::Vector3d row = Eigen::Vector3d::Zero();
    row[j] = 1.0 - t;
    row[j + 1] = t;
    for (int c = 0; c < 4; ++c) a[c].push_back(row), b[c].push_back(bi[c]);
  }
  double exact = 0.0;
  for (int c = 0; c < 4; ++c) exact += exact_l1_minimum(a[c], b[c]);

  SolverSettings s;
  s.extra["delta"] = "1e-7";
  s.extra["tolerance"] = "1e-9";
  s.extra["max-iterations"] = "400";
  const SolverOutput out = p.solve(ctx(), "irls", s);
  EXPECT_TRUE(test::all_finite_in_box(out.tf));
  const double irls = l1_objective(p, out.tf);
  const double least_squares = l1_objective(p, solve_box_constrained(p.cpu_equations()).tf);
  // The test can tell: least squares is clearly worse than the optimum.
  ASSERT_GT(least_squares - exact, 0.05 * exact) << "least squares " << least_squares << ", exact " << exact;
  // The Huber fit of threshold delta is within 160 voxel-channels x delta / 2 of the l1 minimum;
  // the TF is stored in float (1e-7 per residual).
  EXPECT_LE(irls, exact + 160 * (0.5e-7 + 1e-7) + 1e-9 * exact) << "exact " << exact << ", least squares " << least_squares;
  EXPECT_GE(irls, exact - 160 * 1e-7);
}

TEST_F(SolverIrls, MatchesGradientDescentsL1ObjectiveInFarFewerPasses) {
  // A monotone remap with noise, a tenth of the voxels outliers (another colour altogether).
  test::SolverProblem p = test::make_solver_problem(20000, 24, 16, 0.0, 1.0, 29, 0.05, 211);
  std::mt19937 rng(31);
  for (size_t i = 5; i < p.ref_volume.values.size(); i += 10)
    p.ref_volume.values[i] = float(std::uniform_real_distribution<double>(0, 1)(rng));
  p.upload(ctx());
  SolverSettings irls_settings;
  const SolverOutput irls = p.solve(ctx(), "irls", irls_settings);
  SolverSettings gd;
  gd.extra["loss"] = "l1";
  gd.extra["iterations"] = "1500";
  const SolverOutput descent = p.solve(ctx(), "gradient-descent", gd);
  const double f_irls = l1_objective(p, irls.tf), f_gd = l1_objective(p, descent.tf);
  const uint64_t passes = irls.details["iterations"].get<uint64_t>();
  // Measured on lavapipe: IRLS 13 passes (17 without over-relaxation); it ends at or below 1500
  // subgradient steps' objective.
  EXPECT_LE(f_irls, f_gd * (1.0 + 1e-4)) << "irls " << f_irls << " after " << passes << " passes, gd " << f_gd;
  EXPECT_LT(passes, 60u);
  EXPECT_TRUE(irls.details["converged"].get<bool>());
  // One objective per pass; the TF returned is the best of them.
  const auto history = irls.details["objective_per_pass"].get<DetailValue::Numbers>();
  ASSERT_EQ(history.size(), passes);
  EXPECT_NEAR(*std::min_element(history.begin(), history.end()), irls.details["last_loss"].get<double>(), 1e-15);
  EXPECT_LT(history.back(), history.front()) << "the passes improve on the least-squares start";
  // Both far below least squares' l1 objective, which the outliers pull.
  const double f_ls = l1_objective(p, solve_box_constrained(p.cpu_equations()).tf);
  EXPECT_LT(f_irls, 0.97 * f_ls);
}

// The over-relaxed passes (IrlsOptions::overrelax_max) reach at least the plain majorize-minimize
// passes' objective in fewer passes, on the outlier problem above and on a smooth remap; the
// option checks reject values below 1.
TEST_F(SolverIrls, OverRelaxedPassesReachThePlainObjectiveInFewerPasses) {
  for (const uint32_t outlier_every : {10u, 0u}) {
    test::SolverProblem p = test::make_solver_problem(20000, 24, 16, 0.0, 1.0, 29, 0.05, 211);
    std::mt19937 rng(31);
    if (outlier_every)
      for (size_t i = 5; i < p.ref_volume.values.size(); i += outlier_every)
        p.ref_volume.values[i] = float(std::uniform_real_distribution<double>(0, 1)(rng));
    p.upload(ctx());
    VoxelProblem problem = p.problem(ctx());
    IrlsOptions plain;
    plain.overrelax_max = 1.0;
    const IrlsResult a = solve_irls_gpu(problem, plain);
    const IrlsResult b = solve_irls_gpu(problem, IrlsOptions{});
    SCOPED_TRACE("outliers every " + std::to_string(outlier_every) + ": plain " + std::to_string(a.iterations) +
                 " passes, over-relaxed " + std::to_string(b.iterations) + " (" + std::to_string(b.rejected) +
                 " rejected)");
    EXPECT_TRUE(a.converged);
    EXPECT_TRUE(b.converged);
    EXPECT_EQ(a.rejected, 0u);
    EXPECT_LT(b.iterations, a.iterations);
    EXPECT_LE(b.loss, a.loss * (1.0 + 1e-5));
    // The result is the best of the passes, rejected steps included in the history.
    EXPECT_EQ(b.loss, *std::min_element(b.history.begin(), b.history.end()));
  }
  test::SolverProblem small = test::make_solver_problem(100, 8, 8, 0.0, 1.0, 3);
  small.upload(ctx());
  VoxelProblem problem = small.problem(ctx());
  for (auto set : {+[](IrlsOptions& o) { o.overrelax_max = 0.5; }, +[](IrlsOptions& o) { o.overrelax_growth = 0.9; },
                   +[](IrlsOptions& o) { o.overrelax_max = std::numeric_limits<double>::infinity(); }}) {
    IrlsOptions o;
    set(o);
    EXPECT_THROW(solve_irls_gpu(problem, o), std::invalid_argument);
  }
}

TEST_F(SolverIrls, IsBitIdenticalAcrossRunsWarnsWhenCutShortAndRejectsBadFlags) {
  test::SolverProblem p = test::make_solver_problem(20000, 32, 16, 0.0, 1.0, 41, 0.1, 13);
  p.upload(ctx());
  SolverSettings s;
  const SolverOutput a = p.solve(ctx(), "irls", s);
  const SolverOutput b = p.solve(ctx(), "irls", s);
  EXPECT_EQ(a.tf.rgba, b.tf.rgba);
  EXPECT_TRUE(a.warnings.empty());
  s.extra["max-iterations"] = "2";
  const SolverOutput short_run = p.solve(ctx(), "irls", s);
  ASSERT_EQ(short_run.warnings.size(), 1u);
  EXPECT_NE(short_run.warnings[0].find("stopped after 2 passes"), std::string::npos) << short_run.warnings[0];
  for (const auto& [flag, value] : {std::pair{"delta", "0"}, {"delta", "1"}, {"tolerance", "-1"},
                                    {"max-iterations", "0"}, {"max-iterations", "2.5"}}) {
    SolverSettings bad;
    bad.extra[flag] = value;
    EXPECT_THROW(p.solve(ctx(), "irls", bad), std::runtime_error) << flag << "=" << value;
  }
}

}  // namespace
}  // namespace tfm
