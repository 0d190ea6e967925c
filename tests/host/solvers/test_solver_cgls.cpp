// GPU CGLS (`cgls`) and the CPU CGLS baseline (`eigen-cgls`, host/solvers/cgls_cpu.h) against the exact
// normal-equations solution: small and medium problems, split chunks, regularization, rank-
// deficient M, the stop test, and bit-identical results across runs.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <random>

#include <Eigen/Dense>

#include "solver_problem.h"
#include "tfmatch/kernels/device_cgls.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/solvers/cgls_cpu.h"
#include "tfmatch/solvers/eigen_baseline.h"
#include "tfmatch/solvers/solver_cgls.h"
#include "tfmatch/solvers/tridiagonal.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

class SolverCgls : public test::GpuTest {};

// Tolerances: CGLS stops at ||s|| <= 1e-6 ||s0|| (default). With Jacobi scaling D, the error
// obeys |x - x*| <~ cond(D^-1/2 M D^-1/2) * 1e-6 * |x*|; for these uniform-coverage problems the
// scaled condition number is below ~10 (checked against cond(M) in the normal-equations result),
// and float32 iterates add ~1e-6. Measured on lavapipe: <= 5e-6; 1e-4 bounds both with margin.
constexpr double kCglsTolerance = 1e-4;

TEST_F(SolverCgls, MatchesNormalEquationsWhenConstraintsAreInactive) {
  test::SolverProblem p = test::make_solver_problem(5000, 16, 12, 0.2, 0.8, 3);
  p.upload(ctx());
  const SolverOutput out = p.solve(ctx(), "cgls");
  const SolveResult exact = solve_normal_equations(p.cpu_equations());
  ASSERT_EQ(exact.clamped_values, 0u);
  EXPECT_LT(test::max_difference(out.tf, exact.tf), kCglsTolerance);
  EXPECT_LE(out.details["relative_residual"].get<double>(), 1e-6);
  EXPECT_LE(out.details["iterations"].get<int>(), 16 + 4) << "CG on 16 unknowns needs ~16 iterations";
  EXPECT_TRUE(out.warnings.empty());
}

// The solvers' own working sets are checked against the memory budget before they are made, as
// the inputs are: CGLS's per-voxel vectors (on a device whose memory is the host's) and the Eigen
// baseline's explicit A and its transpose went 3.7 to 39 times over --max-memory unchecked.
TEST_F(SolverCgls, WorkingMemoryBeyondTheBudgetIsSaidBeforeItIsMade) {
  test::SolverProblem p = test::make_solver_problem(400000, 16, 12, 0.2, 0.8, 3);
  p.upload(ctx());
  const auto refused = [](auto work, const std::string& what) {
    try {
      work();
    } catch (const MemoryBudgetExceeded& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      return true;
    }
    return false;
  };
  set_memory_budget(resident_memory() + (uint64_t(1) << 20), "--max-memory test");
  EXPECT_TRUE(refused([&] { build_explicit_system(p.ref_volume.values, p.opt_volume.values, p.ref_map, p.opt_map, p.ref_tf); },
                      "the explicit sparse A of 400000 voxels"));
  if (ctx().properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU)
    EXPECT_TRUE(refused([&] { p.solve(ctx(), "cgls"); }, "CGLS: per-voxel vectors of 400000 voxels"));
  set_memory_budget(0, "");
  EXPECT_NO_THROW(p.solve(ctx(), "cgls"));
}

TEST_F(SolverCgls, MediumProblemWithNaNsAndSplitChunks) {
  test::SolverProblem p = test::make_solver_problem(60000, 64, 40, 0.1, 0.9, 4, 0.02, 17);
  p.upload(ctx(), 20480);  // three field chunks
  CglsGpuOptions o;
  o.max_chunk_voxels = 5000;  // voxel vectors in chunks that divide the field chunks
  VoxelProblem problem = p.problem(ctx());
  const CglsGpuResult out = solve_cgls_gpu(problem, o);
  EXPECT_GT(out.voxel_chunks, 3u);
  const SolveResult exact = solve_normal_equations(p.cpu_equations());
  EXPECT_LT(test::max_difference(out.tf, exact.tf), kCglsTolerance);
  EXPECT_TRUE(test::all_finite_in_box(out.tf));
}

// Weighted least squares (--weights): the weighted prepare, gather and scatter passes over voxel
// vectors in blocks of a split field reach the solution of the weighted system (its exact
// assembly, kernels/assemble_normal_equations.h, solved directly).
TEST_F(SolverCgls, WeightedMatchesTheWeightedNormalEquations) {
  test::SolverProblem p = test::make_solver_problem(60001, 48, 40, 0.1, 0.9, 6, 0.3, 17);
  p.upload(ctx(), 20480);
  std::mt19937 rng(8);
  std::vector<float> w(p.ref_volume.values.size());
  for (size_t i = 0; i < w.size(); ++i) w[i] = i % 9 == 4 ? 0.0f : float(rng() % 65537) / 65536.0f;
  const DeviceField weights(ctx(), w, "weights", 20480);
  VoxelProblem problem = p.problem(ctx());
  GpuNormalEquations gpu(ctx(), 48);
  gpu.add(*p.ref, *p.opt, p.ref_map, p.opt_map, *p.ref_tf_buffer, nullptr, &weights);
  const NormalEquations weighted = gpu.result();
  CglsGpuOptions o;
  o.max_chunk_voxels = 5000;
  o.weights = &weights;
  o.weighted_system = &weighted;
  const CglsGpuResult out = solve_cgls_gpu(problem, o);
  EXPECT_GT(out.voxel_chunks, 3u);
  const SolveResult exact = solve_normal_equations(weighted);
  EXPECT_LT(test::max_difference(out.tf, exact.tf), kCglsTolerance);
  const SolveResult plain = solve_normal_equations(p.cpu_equations());
  EXPECT_GT(test::max_difference(exact.tf, plain.tf), 10 * kCglsTolerance) << "the weights should matter";
  o.weighted_system = nullptr;
  EXPECT_THROW(solve_cgls_gpu(problem, o), std::invalid_argument);
}

TEST_F(SolverCgls, LargeTfUsesGlobalAccumulatorsAndSeveralVectorBlocks) {
  // N = 1200: more entries than the vector kernel's 256 invocations, and signed slots (38 KB)
  // beyond lavapipe's 32 KB of shared memory, so the scatter adds straight to memory.
  test::SolverProblem p = test::make_solver_problem(80000, 1200, 50, 0.2, 0.8, 10);
  p.upload(ctx());
  const SolverOutput out = p.solve(ctx(), "cgls");
  const SolveResult exact = solve_normal_equations(p.cpu_equations());
  EXPECT_LT(test::max_difference(out.tf, exact.tf), kCglsTolerance);
  EXPECT_TRUE(out.warnings.empty());
}

TEST_F(SolverCgls, RegularizedMatchesRegularizedNormalEquations) {
  test::SolverProblem p = test::make_solver_problem(8000, 32, 20, 0.2, 0.8, 5, 0.1);
  p.upload(ctx());
  SolverSettings s;
  s.solve.ridge = 0.01;
  s.solve.smooth = 0.1;
  const SolverOutput out = p.solve(ctx(), "cgls", s);
  const SolveResult exact = solve_normal_equations(p.cpu_equations(), s.solve);
  EXPECT_LT(test::max_difference(out.tf, exact.tf), kCglsTolerance);
}

TEST_F(SolverCgls, UnreferencedEntriesWithAndWithoutSmoothness) {
  // The second field covers only part of its range (the range is given wider): entries above
  // ~t = 0.6 are touched by no voxel and M is singular.
  test::SolverProblem p = test::make_solver_problem(6000, 24, 12, 0.2, 0.8, 6);
  p.opt_map = make_mapping({10.0, 30.0}, 24);
  p.upload(ctx());
  const NormalEquations eq = p.cpu_equations();
  ASSERT_EQ(eq.diag[23], 0.0);
  const SolverOutput plain = p.solve(ctx(), "cgls");
  EXPECT_TRUE(test::all_finite_in_box(plain.tf));
  const SolveResult exact = solve_normal_equations(eq);
  // Unreferenced entries: 0, as the normal equations' basic solution sets them.
  EXPECT_LT(test::max_difference(plain.tf, exact.tf), kCglsTolerance);
  SolverSettings s;
  s.solve.smooth = 0.05;
  const SolverOutput smooth = p.solve(ctx(), "cgls", s);
  const SolveResult exact_smooth = solve_normal_equations(eq, s.solve);
  EXPECT_TRUE(test::all_finite_in_box(smooth.tf));
  EXPECT_LT(test::max_difference(smooth.tf, exact_smooth.tf), kCglsTolerance);
}

// Smoothing from as strong as the data to a million times stronger: the preconditioner inverts
// it exactly, so CGLS converges in a handful of iterations to the regularized normal equations'
// solution. Jacobi alone (before 2026-12-06) stopped at the 1000-iteration cap from --smooth 100
// on, with a warning; heavier smoothing ends at the float32 floor, which then says so in the
// details, not in a warning.
// cgls under `smooth` against the normal equations solved in double: within kCglsTolerance, in at
// most 16 iterations, without a warning.
SolverOutput expect_quick_smoothed_fit(Context& ctx, test::SolverProblem& p, double smooth) {
  SCOPED_TRACE("smooth " + std::to_string(smooth));
  SolverSettings s;
  s.solve.smooth = smooth;
  const SolverOutput out = p.solve(ctx, "cgls", s);
  const SolveResult exact = solve_normal_equations(p.cpu_equations(), s.solve);
  EXPECT_LT(test::max_difference(out.tf, exact.tf), kCglsTolerance);
  EXPECT_LE(out.details["iterations"].get<int>(), 16);
  EXPECT_TRUE(out.warnings.empty()) << out.warnings.front();
  return out;
}

TEST_F(SolverCgls, HeavySmoothingConvergesInFewIterations) {
  test::SolverProblem p = test::make_solver_problem(20000, 64, 30, 0.1, 0.9, 11, 0.05);
  p.upload(ctx());
  for (const double smooth : {1.0, 100.0, 1e4, 1e6}) {
    const SolverOutput out = expect_quick_smoothed_fit(ctx(), p, smooth);
    const double residual = out.details["relative_residual"].get<double>();
    const double floor = out.details["residual_floor"].get<double>();
    EXPECT_LE(residual, std::max(1e-6, floor)) << "smooth " << smooth;
    EXPECT_GT(floor, 0.0);
  }
}

// Heavy smoothing over many entries: the float32 floor is measured in the preconditioner's norm,
// where the rounding of x is small beside a smooth error. Measured in the plain norm (before
// 2026-12-06) it stopped these 0.0017 and 0.0011 from the fit (on the 128x128x64 synthetic pair
// at N = 4096 and 16384, --smooth 1e6: 0.027 and 0.04; now 3e-5).
TEST_F(SolverCgls, HeavySmoothingOverManyEntriesReachesTheFit) {
  test::SolverProblem p = test::make_solver_problem(100000, 4096, 30, 0.1, 0.9, 17, 0.05);
  p.upload(ctx());
  for (const double smooth : {1e6, 1e8}) expect_quick_smoothed_fit(ctx(), p, smooth);
}

// The double reference of the GPU iteration: the same preconditioned CGLS per channel on the
// explicit S, its preconditioner diag(S^T S) + R solved densely (no tridiagonal code). At a
// smoothing whose float32 floor stays below the tolerance, each channel takes the same number of
// iterations within 2, and both land on the normal equations' solution.
TEST_F(SolverCgls, SmoothedIterationsMatchTheDoubleReference) {
  test::SolverProblem p = test::make_solver_problem(12000, 48, 30, 0.1, 0.9, 12, 0.05, 41);
  p.upload(ctx());
  SolverSettings settings;
  settings.solve.smooth = 3.0;
  settings.extra["tolerance"] = "1e-5";
  const SolverOutput out = p.solve(ctx(), "cgls", settings);
  const NormalEquations eq = p.cpu_equations();
  const Regularization reg = absolute_regularization(eq, settings.solve);
  const uint32_t n = 48;
  std::vector<Eigen::Triplet<double>> terms, r_terms;
  std::vector<std::array<double, 4>> rows_b;
  for (size_t i = 0; i < p.ref_volume.values.size(); ++i) {
    uint32_t j;
    float w;
    double b[4];
    if (!p.voxel_terms(i, j, w, b)) continue;
    const int row = int(rows_b.size());
    terms.emplace_back(row, int(j), 1.0 - double(w));
    terms.emplace_back(row, int(j) + 1, double(w));
    rows_b.push_back({b[0], b[1], b[2], b[3]});
  }
  Eigen::SparseMatrix<double, Eigen::RowMajor> a(Eigen::Index(rows_b.size()), n);
  a.setFromTriplets(terms.begin(), terms.end());
  for (uint32_t j = 0; j < n; ++j) {
    r_terms.emplace_back(j, j, reg.smooth * ((j > 0) + (j + 1 < n)));
    if (j + 1 < n) r_terms.emplace_back(j, j + 1, -reg.smooth), r_terms.emplace_back(j + 1, j, -reg.smooth);
  }
  Eigen::SparseMatrix<double> r(n, n);
  r.setFromTriplets(r_terms.begin(), r_terms.end());
  Eigen::MatrixXd precond = Eigen::MatrixXd(r);
  const Eigen::SparseMatrix<double> ata = Eigen::SparseMatrix<double>(a.transpose()) * a;
  for (uint32_t j = 0; j < n; ++j) precond(j, j) += ata.coeff(j, j);
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(precond);
  const SolveResult exact = solve_normal_equations(eq, settings.solve);
  const std::vector<double> gpu_iterations = out.details["iterations_per_channel"].get<DetailValue::Numbers>();
  ASSERT_EQ(gpu_iterations.size(), 4u);
  for (int c = 0; c < 4; ++c) {
    Eigen::VectorXd b(Eigen::Index(rows_b.size()));
    for (size_t i = 0; i < rows_b.size(); ++i) b[Eigen::Index(i)] = rows_b[i][size_t(c)];
    CglsOptions o;
    o.tolerance = 1e-5;
    const CglsResult cpu = cgls_preconditioned(
        a, b, r, [&ldlt](const Eigen::VectorXd& v) -> Eigen::VectorXd { return ldlt.solve(v); }, o);
    ASSERT_TRUE(cpu.converged) << "channel " << c;
    EXPECT_NEAR(gpu_iterations[size_t(c)], double(cpu.iterations), 2.0) << "channel " << c;
    for (uint32_t j = 0; j < n; ++j) {
      EXPECT_NEAR(cpu.x[j], exact.x(j, c), 1e-4) << "channel " << c << " entry " << j;
      EXPECT_NEAR(out.tf.rgba[j][size_t(c)], std::clamp(exact.x(j, c), 0.0, 1.0), kCglsTolerance)
          << "channel " << c << " entry " << j;
    }
  }
}

// The device loop refuses factors of the wrong sizes before it makes a buffer (a long multiplier
// list once overran the N-entry copy), and the preconditioner is Jacobi without smoothing and the
// LDL^T of diag(M) + R with it.
TEST_F(SolverCgls, PreconditionerFactorsAreCheckedAndMatchTheirDefinition) {
  const uint32_t n = 9;
  for (const CglsFactors& bad : {CglsFactors{std::vector<float>(n - 1, 1.0f), {}},
                                 CglsFactors{std::vector<float>(n, 1.0f), std::vector<float>(n + 40, 0.5f)},
                                 CglsFactors{std::vector<float>(n, 1.0f), std::vector<float>(n - 2, 0.5f)}})
    EXPECT_THROW(DeviceCgls(ctx(), n, bad, {}), std::invalid_argument);
  EXPECT_NO_THROW(DeviceCgls(ctx(), n, CglsFactors{std::vector<float>(n, 1.0f), std::vector<float>(n - 1, 0.5f)}, {}));

  test::SolverProblem p = test::make_solver_problem(3000, 16, 20, 0.1, 0.9, 5);
  const NormalEquations eq = p.cpu_equations();
  const Tridiagonal m = regularized_matrix(eq, {});
  const CglsFactors jacobi = cgls_preconditioner(eq, {});
  EXPECT_TRUE(jacobi.lower.empty());
  for (uint32_t j = 0; j < 16; ++j) EXPECT_FLOAT_EQ(jacobi.inv_pivot[j], float(1.0 / m.diag[j]));
  const Regularization reg{0.0, 7.0};
  const CglsFactors smoothed = cgls_preconditioner(eq, reg);
  ASSERT_EQ(smoothed.lower.size(), 15u);
  // (L D L^T) e_j, column by column, against diag(M) + 7 D^T D.
  for (uint32_t j = 0; j < 16; ++j)
    for (uint32_t k = 0; k < 16; ++k) {
      double sum = 0.0;  // sum_i L_ji D_i L_ki over i in {j-1, j} and {k-1, k}
      for (uint32_t i = 0; i < 16; ++i) {
        const double l_ji = i == j ? 1.0 : (i + 1 == j ? smoothed.lower[i] : 0.0);
        const double l_ki = i == k ? 1.0 : (i + 1 == k ? smoothed.lower[i] : 0.0);
        sum += l_ji * l_ki / double(smoothed.inv_pivot[i]);
      }
      const double d_t_d = j == k ? double((j > 0) + (j + 1 < 16)) : (j + 1 == k || k + 1 == j ? -1.0 : 0.0);
      const double want = (j == k ? m.diag[j] : 0.0) + 7.0 * d_t_d;
      EXPECT_NEAR(sum, want, 1e-5 * std::abs(m.diag[j] + 14.0)) << j << "," << k;
    }
}

TEST_F(SolverCgls, IsBitIdenticalAcrossRuns) {
  test::SolverProblem p = test::make_solver_problem(20000, 64, 30, 0.1, 0.9, 7, 0.05);
  p.upload(ctx());
  const SolverOutput a = p.solve(ctx(), "cgls");
  const SolverOutput b = p.solve(ctx(), "cgls");
  EXPECT_EQ(a.tf.rgba, b.tf.rgba);
  EXPECT_EQ(a.details["iterations_per_channel"], b.details["iterations_per_channel"]);
}

TEST_F(SolverCgls, IterationCapStopsAndWarns) {
  test::SolverProblem p = test::make_solver_problem(5000, 32, 20, 0.2, 0.8, 8);
  p.upload(ctx());
  SolverSettings s;
  s.extra["max-iterations"] = "3";
  const SolverOutput out = p.solve(ctx(), "cgls", s);
  EXPECT_EQ(out.details["iterations"].get<int>(), 3);
  EXPECT_GT(out.details["relative_residual"].get<double>(), 1e-6);
  ASSERT_EQ(out.warnings.size(), 1u);
  EXPECT_NE(out.warnings[0].find("CGLS stopped at --max-iterations 3"), std::string::npos) << out.warnings[0];
  EXPECT_NE(out.warnings[0].find("normal-equations and qp solve the same regularized system exactly"),
            std::string::npos);
  EXPECT_EQ(out.warnings[0].find("no smaller than at the start"), std::string::npos) << out.warnings[0];
  s.extra["tolerance"] = "2";
  EXPECT_THROW(p.solve(ctx(), "cgls", s), std::runtime_error);
}

TEST_F(SolverCgls, EigenCglsMatchesNormalEquations) {
  test::SolverProblem p = test::make_solver_problem(5000, 32, 20, 0.2, 0.8, 9, 0.05, 23);
  p.upload(ctx());
  const SolveResult exact = solve_normal_equations(p.cpu_equations());
  const SolverOutput out = p.solve(ctx(), "eigen-cgls");
  // Double precision: only the stop test (1e-6, scaled condition number < 10) limits it.
  EXPECT_LT(test::max_difference(out.tf, exact.tf), 1e-5);
  EXPECT_LE(out.details["relative_residual"].get<double>(), 1e-6);
}

TEST(CglsCpu, RegularizedExplicitSystemMatchesDirectSolve) {
  // A random explicit system with a ridge, solved to 1e-12 and compared with a dense solve.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const int rows = 300, cols = 12;
  Eigen::SparseMatrix<double, Eigen::RowMajor> a(rows, cols);
  std::vector<Eigen::Triplet<double>> t;
  Eigen::VectorXd b(rows);
  for (int r = 0; r < rows; ++r) {
    const int j = int(rng() % (cols - 1));
    const double w = u(rng);
    t.emplace_back(r, j, 1.0 - w);
    t.emplace_back(r, j + 1, w);
    b[r] = u(rng);
  }
  a.setFromTriplets(t.begin(), t.end());
  Eigen::SparseMatrix<double> reg(cols, cols);
  reg.setIdentity();
  reg *= 0.5;
  CglsOptions o;
  o.tolerance = 1e-12;
  const CglsResult r = cgls_jacobi(a, b, reg, o);
  const Eigen::MatrixXd dense = Eigen::MatrixXd(a.transpose() * a) + Eigen::MatrixXd(reg);
  const Eigen::VectorXd x = dense.ldlt().solve(Eigen::VectorXd(a.transpose() * b));
  EXPECT_TRUE(r.converged);
  EXPECT_LE(r.iterations, 2u * cols);
  EXPECT_LT((r.x - x).cwiseAbs().maxCoeff(), 1e-10);
}

}  // namespace
}  // namespace tfm
