// The host solver of the tridiagonal normal equations against independent dense least-squares
// solves of the explicit A, with and without regularization; singular and recovery cases.
#include <cmath>
#include <string>
#include <random>
#include <vector>

#include <Eigen/Dense>

#include "solver_problem.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/synthetic.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/solvers/eigen_baseline.h"
#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/optimize.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

struct Problem {
  std::vector<float> ref, opt;
  TransferFunction ref_tf;
  FieldMapping rm, om;
};

Problem small_problem(size_t voxels, uint32_t n, uint32_t seed, double opt_hi = 1.0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Problem p;
  p.ref.resize(voxels);
  p.opt.resize(voxels);
  for (size_t i = 0; i < voxels; ++i) {
    p.ref[i] = u(rng);
    p.opt[i] = float(opt_hi) * u(rng);
  }
  p.ref_tf.rgba.resize(9);
  for (auto& e : p.ref_tf.rgba) e = {u(rng), u(rng), u(rng), u(rng)};
  p.rm = make_mapping({0, 1}, 9);
  p.om = make_mapping({0, 1}, n);
  return p;
}

// x as N x 4 from a solution vector of the explicit system (index 4j + c).
Eigen::Matrix<double, Eigen::Dynamic, 4> unstack(const Eigen::VectorXd& v, uint32_t n) {
  Eigen::Matrix<double, Eigen::Dynamic, 4> x(n, 4);
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) x(j, c) = v(4 * j + c);
  return x;
}

// Dense least squares of [A; sqrt(ridge) I; sqrt(smooth) (D (x) I4)] by Householder QR on the
// explicit matrix: independent of the normal equations (no A^T A is formed).
Eigen::VectorXd dense_least_squares(const ExplicitSystem& s, uint32_t n, double ridge, double smooth) {
  Eigen::MatrixXd a = Eigen::MatrixXd(s.a);
  const Eigen::Index m = a.rows(), cols = 4 * n;
  const Eigen::Index extra = (ridge > 0 ? cols : 0) + (smooth > 0 ? 4 * (n - 1) : 0);
  Eigen::MatrixXd big = Eigen::MatrixXd::Zero(m + extra, cols);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(m + extra);
  big.topRows(m) = a;
  rhs.head(m) = s.b;
  Eigen::Index row = m;
  if (ridge > 0)
    for (Eigen::Index k = 0; k < cols; ++k) big(row++, k) = std::sqrt(ridge);
  if (smooth > 0)
    for (uint32_t j = 0; j + 1 < n; ++j)
      for (int c = 0; c < 4; ++c, ++row) {
        big(row, 4 * j + c) = -std::sqrt(smooth);
        big(row, 4 * (j + 1) + c) = std::sqrt(smooth);
      }
  return big.colPivHouseholderQr().solve(rhs);
}

double mean_diag(const NormalEquations& eq) {
  double s = 0;
  for (double d : eq.diag) s += d;
  return s / eq.n;
}

TEST(NormalEquationsSolver, MatchesDenseLeastSquares) {
  for (uint32_t n : {2u, 5u, 16u}) {
    Problem p = small_problem(600, n, 10 + n);
    NormalEquations eq = assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf);
    ExplicitSystem sys = build_explicit_system(p.ref, p.opt, p.rm, p.om, p.ref_tf);
    Eigen::VectorXd dense = dense_least_squares(sys, n, 0, 0);
    for (Factorization f : {Factorization::LDLT, Factorization::Auto}) {
      SolveOptions o;
      o.factorization = f;
      SolveResult r = solve_normal_equations(eq, o);
      // Well conditioned (cond < 1e3 here): both agree to near double rounding times cond.
      EXPECT_LT(r.cond, 1e3);
      EXPECT_LE((r.x - unstack(dense, n)).cwiseAbs().maxCoeff(), 1e-9) << "n=" << n;
    }
  }
}

TEST(NormalEquationsSolver, RegularizationMatchesAugmentedDenseSystem) {
  const uint32_t n = 12;
  Problem p = small_problem(400, n, 77);
  NormalEquations eq = assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf);
  ExplicitSystem sys = build_explicit_system(p.ref, p.opt, p.rm, p.om, p.ref_tf);
  const double md = mean_diag(eq);
  for (auto [ridge, smooth] : {std::pair{0.1, 0.0}, std::pair{0.0, 0.5}, std::pair{0.05, 2.0}}) {
    SolveOptions o;
    o.ridge = ridge;
    o.smooth = smooth;
    SolveResult r = solve_normal_equations(eq, o);
    Eigen::VectorXd dense = dense_least_squares(sys, n, ridge * md, smooth * md);
    EXPECT_LE((r.x - unstack(dense, n)).cwiseAbs().maxCoeff(), 1e-9) << ridge << " " << smooth;
  }
}

TEST(NormalEquationsSolver, ConditionNumberMatchesDenseEigenvalues) {
  Problem p = small_problem(300, 10, 5);
  NormalEquations eq = assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(eq.dense_m());
  SolveResult r = solve_normal_equations(eq);
  double cond = es.eigenvalues().maxCoeff() / es.eigenvalues().minCoeff();
  EXPECT_NEAR(r.cond / cond, 1.0, 1e-10);
  EXPECT_EQ(r.factorization, "ldlt");
}

// Entries no voxel touches make M singular: the rank-revealing solve sets them to 0, the referenced
// entries still solve their least-squares problem, and nothing is NaN; smoothing fills them.
TEST(NormalEquationsSolver, UnreferencedEntriesHandled) {
  const uint32_t n = 10;
  Problem p = small_problem(500, n, 9, /*opt_hi=*/0.5);  // opt only in [0, 0.5]: entries 5.. unused
  // x = 9 * opt lies in [0, 4.5]: entries 0..5 are touched, 6..9 are not.
  NormalEquations eq = assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf);
  SolveResult r = solve_normal_equations(eq);
  EXPECT_TRUE(std::isinf(r.cond));
  EXPECT_EQ(r.factorization, "min-norm-ldlt");
  EXPECT_GE(r.unreferenced_entries, 4u);
  EXPECT_TRUE(r.x.allFinite());
  EXPECT_FALSE(r.warnings.empty());
  for (uint32_t j = 0; j < n; ++j)
    if (eq.diag[j] == 0.0)
      for (int c = 0; c < 4; ++c) EXPECT_EQ(r.x(j, c), 0.0);
  // The referenced block equals the dense least-squares solution restricted to its columns.
  ExplicitSystem sys = build_explicit_system(p.ref, p.opt, p.rm, p.om, p.ref_tf);
  uint32_t used = 0;
  while (used < n && eq.diag[used] != 0.0) ++used;
  Eigen::MatrixXd a = Eigen::MatrixXd(sys.a).leftCols(4 * used);
  Eigen::VectorXd dense = a.colPivHouseholderQr().solve(sys.b);
  EXPECT_LE((r.x.topRows(used) - unstack(dense, used)).cwiseAbs().maxCoeff(), 1e-8);

  SolveOptions smooth;
  smooth.smooth = 0.01;
  SolveResult rs = solve_normal_equations(eq, smooth);
  EXPECT_TRUE(std::isfinite(rs.cond));
  EXPECT_TRUE(rs.x.allFinite());
  // With a smoothness prior the unreferenced tail continues the last referenced entry.
  for (int c = 0; c < 4; ++c) EXPECT_NEAR(rs.x(n - 1, c), rs.x(used - 1, c), 1e-6);
}

// A smoothness weight far above M's (s >> voxels per entry) leaves one direction to the data, the
// constant TF, so x tends to the mean reference colour (S 1 = 1: 1^T S^T b / 1^T M 1 = mean b),
// away from it by O(N^2 / s). The rank decision must not take the constant direction for noise
// (its pivot is of M's size, not of M + s D^T D's): it did, and --smooth 1e8 gave a TF of zeros.
// Moderate weights are checked against the dense augmented least squares, heavy ones against the
// mean; neither warns, since the exact regularization makes x no less certain.
TEST(NormalEquationsSolver, HeavySmoothingTendsToTheMeanReferenceColour) {
  for (double opt_hi : {1.0, 0.5}) {  // 0.5: entries 6.. are touched by no voxel
    const uint32_t n = 12;
    Problem p = small_problem(500, n, 21, opt_hi);
    NormalEquations eq = assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf);
    ExplicitSystem sys = build_explicit_system(p.ref, p.opt, p.rm, p.om, p.ref_tf);
    Eigen::RowVector4d mean = Eigen::RowVector4d::Zero();
    const Eigen::Index voxels = sys.b.size() / 4;
    for (Eigen::Index i = 0; i < voxels; ++i)
      for (int c = 0; c < 4; ++c) mean(c) += sys.b(4 * i + c);
    mean /= double(voxels);
    const double md = mean_diag(eq);
    for (double smooth : {1e2, 1e4, 1e6, 1e8, kMaxRelativeSmooth}) {
      SolveOptions o;
      o.smooth = smooth;
      const SolveResult r = solve_normal_equations(eq, o);
      SCOPED_TRACE("opt_hi " + std::to_string(opt_hi) + ", smooth " + std::to_string(smooth));
      ASSERT_EQ(r.x.rows(), Eigen::Index(n));
      EXPECT_EQ(r.factorization, "ldlt");
      EXPECT_EQ(r.dependent_entries, 0u);
      EXPECT_TRUE(std::isfinite(r.cond));
      EXPECT_TRUE(r.warnings.empty()) << r.warnings.front();
      EXPECT_LT(r.error_amplification, 1e3);
      if (smooth <= 1e4) {
        Eigen::VectorXd dense = dense_least_squares(sys, n, 0.0, smooth * md);
        EXPECT_LE((r.x - unstack(dense, n)).cwiseAbs().maxCoeff(), 1e-9);
      }
      const double bound = 10.0 * n * n / smooth + 1e-6;  // and M and S^T b carry float32 rounding
      for (uint32_t j = 0; j < n; ++j)
        for (int c = 0; c < 4; ++c) EXPECT_NEAR(r.x(j, c), mean(c), bound) << "entry " << j << " channel " << c;
    }
  }
}

// Beyond kMaxRelativeSmooth double rounding outgrows the data (1.8e-4 at 1e13): refused, as are
// weights that are no weights, naming the flag, by the one check every voxel solver goes through.
TEST(NormalEquationsSolver, WeightsBeyondWhatDoublesResolveAreRefused) {
  Problem p = small_problem(200, 8, 3);
  NormalEquations eq = assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf);
  auto refused = [&](double ridge, double smooth, const std::string& needle) {
    SolveOptions o;
    o.ridge = ridge;
    o.smooth = smooth;
    try {
      solve_normal_equations(eq, o);
      ADD_FAILURE() << "ridge " << ridge << ", smooth " << smooth << " were accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
    EXPECT_THROW(absolute_regularization(eq, o), std::invalid_argument);
  };
  refused(0.0, 2 * kMaxRelativeSmooth, "--smooth 2e+09 is beyond 1e+09");
  refused(0.0, -1.0, "--smooth");
  refused(std::nan(""), 0.0, "--ridge");
  refused(INFINITY, 0.0, "--ridge");
  refused(1e307, 0.0, "--ridge 1e+307 is beyond 1e+100");
  SolveOptions huge_ridge;  // a ridge only shrinks x towards 0, with no cancellation: any finite one
  huge_ridge.ridge = 1e30;
  EXPECT_LE(solve_normal_equations(eq, huge_ridge).x.cwiseAbs().maxCoeff(), 1e-29);
  huge_ridge.ridge = kMaxRelativeRidge;
  EXPECT_LE(solve_normal_equations(eq, huge_ridge).x.cwiseAbs().maxCoeff(), 1e-99);
}

// The warning measures how much M's float32 error can move x: cond(M) without regularization, and
// lambda_max(M) / lambda_min(M + R) with it, both against dense eigenvalues.
TEST(NormalEquationsSolver, ErrorAmplificationMatchesDenseEigenvalues) {
  Problem p = small_problem(300, 10, 5);
  NormalEquations eq = assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf);
  const Eigen::MatrixXd m = eq.dense_m();
  const double data_max = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m).eigenvalues().maxCoeff();
  const SolveResult plain = solve_normal_equations(eq);
  EXPECT_EQ(plain.error_amplification, plain.cond);
  SolveOptions o;
  o.ridge = 0.5;
  o.smooth = 3.0;
  const SolveResult r = solve_normal_equations(eq, o);
  const Regularization reg = absolute_regularization(eq, o);
  Eigen::MatrixXd mr = m;
  for (uint32_t j = 0; j < eq.n; ++j) {
    mr(j, j) += reg.ridge + reg.smooth * ((j == 0 || j + 1 == eq.n) ? 1.0 : 2.0);
    if (j + 1 < eq.n) mr(j, j + 1) = mr(j + 1, j) = mr(j, j + 1) - reg.smooth;
  }
  const double reg_min = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(mr).eigenvalues().minCoeff();
  EXPECT_NEAR(r.error_amplification / (data_max / reg_min), 1.0, 1e-10);
  EXPECT_LT(r.error_amplification, r.cond);
}

// The warning's advice names what can run: cgls reads the fields, so after a streamed assembly it
// says that cgls needs them in memory, in one process (not --stream on, not under MPI).
TEST(NormalEquationsSolver, ConditionAdviceNamesWhatCanRun) {
  Problem p = small_problem(300, 10, 5);
  const NormalEquations eq = assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf);
  SolveOptions o;
  o.cond_warning = 1.0;  // every system warns
  const SolveResult whole = solve_normal_equations(eq, o);
  ASSERT_EQ(whole.warnings.size(), 1u);
  EXPECT_NE(whole.warnings[0].find("consider --solver cgls or --smooth"), std::string::npos) << whole.warnings[0];
  o.streamed = true;
  const SolveResult streamed = solve_normal_equations(eq, o);
  ASSERT_EQ(streamed.warnings.size(), 1u);
  EXPECT_NE(streamed.warnings[0].find("consider --solver cgls (--stream off, in one process) or --smooth"),
            std::string::npos)
      << streamed.warnings[0];
  EXPECT_EQ(streamed.x, whole.x);
}

using SolverGpuTest = test::GpuTest;

// The solver's details carry what the warning weighs beside cond(M + R): smoothing raises cond,
// not the error amplification, and neither warns here.
TEST_F(SolverGpuTest, DetailsCarryTheErrorAmplification) {
  test::SolverProblem p = test::make_solver_problem(5000, 16, 12, 0.2, 0.8, 3);
  p.upload(ctx());
  SolverSettings s;
  s.solve.smooth = 1e4;
  const SolverOutput out = p.solve(ctx(), "normal-equations", s);
  ASSERT_TRUE(out.details["cond"].is_number() && out.details["error_amplification"].is_number());
  EXPECT_GT(out.details["cond"].get<double>(), 1e4);
  EXPECT_LT(out.details["error_amplification"].get<double>(), 1e2);
  EXPECT_TRUE(out.warnings.empty());
}

// GPU-assembled and CPU-assembled systems give the same TF (to cond * assembly error).
TEST_F(SolverGpuTest, GpuAssemblyGivesTheSameSolution) {
  Problem p = small_problem(50000, 32, 21);
  DeviceField r(ctx(), p.ref, "ref"), o(ctx(), p.opt, "opt");
  Buffer tf = upload_tf(ctx(), p.ref_tf, "tf");
  GpuNormalEquations gpu(ctx(), 32);
  gpu.add(r, o, p.rm, p.om, tf);
  SolveResult g = solve_normal_equations(gpu.result());
  SolveResult c = solve_normal_equations(assemble_normal_equations_cpu(p.ref, p.opt, p.rm, p.om, p.ref_tf));
  EXPECT_LE((g.x - c.x).cwiseAbs().maxCoeff(), c.cond * 1e-6);
}

// Recovery: F_o = g(F_r) with g monotone. The piecewise-linear interpolant I of
// f = T_r o g^-1 at the optimized TF's nodes is one candidate TF, so the least-squares optimum
// has voxel RMSE <= RMSE(I), which is computed here directly on the voxels; that bound shrinks
// as O(h^2) with the node spacing h = 1/(N-1). The reference TF is fine (256 entries) and
// smooth, so the bound is small, and the field shown with the reference TF is far worse.
TEST_F(SolverGpuTest, RecoversMonotoneRemap) {
  Volume ref = synthetic_reference(40, 36, 30);
  auto g = [](double t) { return 10.0 + 90.0 * t * t; };  // monotone on [0,1]
  auto g_inv = [](double s) { return std::sqrt(std::max(0.0, (s - 10.0) / 90.0)); };
  Volume opt = ref;
  for (float& v : opt.values) v = float(g(v));
  TransferFunction ref_tf = demo_transfer_function(256);
  const uint32_t n = 64;
  FieldRange rr = resolve_range(ref.values, nullptr, "ref"), orr = resolve_range(opt.values, nullptr, "opt");
  FieldMapping rm = make_mapping(rr, 256), om = make_mapping(orr, n);
  DeviceField dr(ctx(), ref.values, "ref"), dopt(ctx(), opt.values, "opt");
  Buffer tfb = upload_tf(ctx(), ref_tf, "ref tf");
  GpuNormalEquations gpu(ctx(), n);
  gpu.add(dr, dopt, rm, om, tfb);
  SolveResult sol = solve_normal_equations(gpu.result());

  // Candidate: interpolate f at the nodes s_j = lo + j (hi-lo)/(N-1).
  TransferFunction candidate;
  candidate.rgba.resize(n);
  for (uint32_t j = 0; j < n; ++j) {
    double s = orr.lo + (orr.hi - orr.lo) * j / (n - 1);
    double t = (g_inv(s) - rr.lo) / (rr.hi - rr.lo);
    candidate.rgba[j] = ref_tf.eval(t);
  }
  Buffer cand = upload_tf(ctx(), candidate, "candidate"), opt_tf = upload_tf(ctx(), sol.tf, "optimized");
  VoxelLoss bound = voxel_loss_gpu(ctx(), dr, dopt, rm, om, tfb, cand);
  VoxelLoss after = voxel_loss_gpu(ctx(), dr, dopt, rm, om, tfb, opt_tf);
  VoxelLoss before = voxel_loss_gpu(ctx(), dr, dopt, rm, make_mapping(orr, 256), tfb, tfb);
  std::printf("recovery: RMSE before %.4f, interpolant bound %.5f, optimized %.5f\n", before.rmse(), bound.rmse(),
              after.rmse());
  EXPECT_LE(after.rmse(), bound.rmse() * (1 + 1e-6) + 1e-6);
  EXPECT_LT(bound.rmse(), 0.02);
  EXPECT_GT(before.rmse(), 10 * bound.rmse());
}

// run_optimize's voxel RMSE before and after comes from the assembled system, with a second
// assembly only when the reference TF has another size; it equals the direct pass over the
// voxels (voxel_loss_gpu) to float rounding, and the mean absolute error is measured only on
// request.
TEST_F(SolverGpuTest, OptimizeLossComesFromTheSystem) {
  Volume ref = synthetic_reference(37, 29, 23);
  Volume opt = synthetic_remapped(ref);
  for (uint32_t ref_entries : {64u, 256u}) {
    for (const char* solver : {"normal-equations", "eigen-normal-equations"}) {
      SCOPED_TRACE(std::string(solver) + ", reference TF of " + std::to_string(ref_entries) + " entries");
      OptimizeRequest req;
      req.ref = &ref;
      req.field = &opt;
      req.ref_tf = demo_transfer_function(ref_entries);
      req.tf_size = 64;
      req.solver = solver;
      const OptimizeResult r = run_optimize(ctx(), req);
      bool voxel_pass = false;
      for (const PhaseTime& p : r.phases) voxel_pass = voxel_pass || p.name == "voxel MAE";
      EXPECT_FALSE(voxel_pass);
      EXPECT_TRUE(std::isnan(r.after.mae()));

      DeviceField dr(ctx(), ref.values, "ref"), dopt(ctx(), opt.values, "opt");
      Buffer rtf = upload_tf(ctx(), req.ref_tf, "ref tf"), otf = upload_tf(ctx(), r.tf, "opt tf");
      const FieldMapping rm = make_mapping(r.ref_range, ref_entries);
      const VoxelLoss before = voxel_loss_gpu(ctx(), dr, dopt, rm, make_mapping(r.field_range, ref_entries), rtf, rtf);
      const VoxelLoss after = voxel_loss_gpu(ctx(), dr, dopt, rm, make_mapping(r.field_range, 64), rtf, otf);
      EXPECT_NEAR(r.before.rmse(), before.rmse(), 1e-6 * before.rmse());
      EXPECT_NEAR(r.after.rmse(), after.rmse(), 1e-6 * after.rmse());
      EXPECT_EQ(r.after.voxels, after.voxels);

      req.voxel_mae = true;
      const OptimizeResult with_mae = run_optimize(ctx(), req);
      EXPECT_NEAR(with_mae.after.mae(), after.mae(), 1e-9);
      EXPECT_NEAR(with_mae.before.mae(), before.mae(), 1e-9);
    }
  }
}

}  // namespace
}  // namespace tfm
