// The box-constrained least-squares solver (host/solvers/box_qp.h) against independent references on the
// explicit dense system: exhaustive enumeration of active sets for tiny N, a long projected-
// gradient run for medium N; KKT checks; active and inactive constraints; rank-deficient M.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Dense>

#include "tfmatch/solvers/box_qp.h"

namespace tfm {
namespace {

// An explicit voxel system: S (voxels x N, two non-zeros per row) and b (voxels x 4).
struct DenseSystem {
  Eigen::MatrixXd s;
  Eigen::MatrixX4d b;
};

// Random TF coordinates in cells [first_cell, last_cell); b from `colour(t)` per channel, t the
// voxel's position in [0,1].
template <class Colour>
DenseSystem make_system(size_t voxels, uint32_t n, uint32_t seed, Colour colour, uint32_t first_cell = 0,
                        uint32_t last_cell = 0) {
  if (last_cell == 0) last_cell = n - 1;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  DenseSystem d{Eigen::MatrixXd::Zero(Eigen::Index(voxels), n), Eigen::MatrixX4d(Eigen::Index(voxels), 4)};
  for (size_t i = 0; i < voxels; ++i) {
    const uint32_t j = first_cell + uint32_t(rng() % (last_cell - first_cell));
    const double w = u(rng);
    d.s(Eigen::Index(i), j) = 1.0 - w;
    d.s(Eigen::Index(i), j + 1) = w;
    const double t = (j + w) / (n - 1);
    for (int c = 0; c < 4; ++c) d.b(Eigen::Index(i), c) = colour(t, c, u(rng));
  }
  return d;
}

NormalEquations equations_of(const DenseSystem& d) {
  const uint32_t n = uint32_t(d.s.cols());
  const Eigen::MatrixXd m = d.s.transpose() * d.s;
  NormalEquations eq(n);
  for (uint32_t j = 0; j < n; ++j) eq.diag[j] = m(j, j);
  for (uint32_t j = 0; j + 1 < n; ++j) eq.off[j] = m(j, j + 1);
  eq.rhs = d.s.transpose() * d.b;
  for (int c = 0; c < 4; ++c) eq.btb[size_t(c)] = d.b.col(c).squaredNorm();
  eq.voxels = uint64_t(d.s.rows());
  return eq;
}

// Exhaustive reference for tiny N: every assignment of each component to lower bound, upper
// bound or free; the free part solved by a dense least-squares (minimum norm) solve of the
// explicit S; the feasible assignment with the smallest ||S x - b||^2 wins.
Eigen::VectorXd exhaustive_box_lsq(const Eigen::MatrixXd& s, const Eigen::VectorXd& b, double* best_objective) {
  const Eigen::Index n = s.cols();
  size_t combos = 1;
  for (Eigen::Index j = 0; j < n; ++j) combos *= 3;
  double best = INFINITY;
  Eigen::VectorXd best_x;
  for (size_t code = 0; code < combos; ++code) {
    Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
    std::vector<Eigen::Index> free;
    size_t k = code;
    for (Eigen::Index j = 0; j < n; ++j, k /= 3) {
      if (k % 3 == 0) x[j] = 0.0;
      else if (k % 3 == 1) x[j] = 1.0;
      else free.push_back(j);
    }
    if (!free.empty()) {
      Eigen::MatrixXd sf(s.rows(), Eigen::Index(free.size()));
      for (size_t f = 0; f < free.size(); ++f) sf.col(Eigen::Index(f)) = s.col(free[f]);
      const Eigen::VectorXd xf = sf.completeOrthogonalDecomposition().solve(b - s * x);
      bool feasible = true;
      for (size_t f = 0; f < free.size(); ++f) {
        feasible = feasible && xf[Eigen::Index(f)] >= -1e-12 && xf[Eigen::Index(f)] <= 1.0 + 1e-12;
        x[free[f]] = std::clamp(xf[Eigen::Index(f)], 0.0, 1.0);
      }
      if (!feasible) continue;
    }
    const double objective = (s * x - b).squaredNorm();
    if (objective < best) best = objective, best_x = x;
  }
  *best_objective = best;
  return best_x;
}

// Medium reference: accelerated projected gradient (FISTA) on ||S x - b||^2 over the box, step
// 1 / L with L = 2 lambda_max(S^T S), run far past convergence.
Eigen::VectorXd projected_gradient_box_lsq(const Eigen::MatrixXd& s, const Eigen::VectorXd& b, int iterations) {
  const Eigen::MatrixXd m = s.transpose() * s;
  const double lipschitz = 2.0 * Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m).eigenvalues().maxCoeff();
  const Eigen::VectorXd stb = s.transpose() * b;
  Eigen::VectorXd x = Eigen::VectorXd::Constant(s.cols(), 0.5), y = x;
  double t = 1.0;
  for (int k = 0; k < iterations; ++k) {
    const Eigen::VectorXd grad = 2.0 * (m * y - stb);
    const Eigen::VectorXd next = (y - grad / lipschitz).cwiseMax(0.0).cwiseMin(1.0);
    const double t_next = 0.5 * (1.0 + std::sqrt(1.0 + 4.0 * t * t));
    y = next + ((t - 1.0) / t_next) * (next - x);
    x = next;
    t = t_next;
  }
  return x;
}

double objective(const DenseSystem& d, const Eigen::MatrixX4d& x, int c) {
  return (d.s * x.col(c) - d.b.col(c)).squaredNorm();
}

// A step in colour at t = 0.5 (and its complement): a piecewise-linear fit overshoots next to
// the jump, so the unconstrained solution leaves [0,1] and bounds become active.
double step_colour(double t, int c, double) { return (t > 0.47) == (c % 2 == 0) ? 1.0 : 0.0; }
// A smooth colour well inside (0,1): no bound is active.
double smooth_colour(double t, int c, double) { return 0.5 + 0.3 * std::sin(3.0 * t + c); }

TEST(BoxQp, TinyProblemsMatchExhaustiveEnumeration) {
  for (uint32_t seed = 1; seed <= 6; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    // Colours outside [0,1] too, so that many bound patterns occur.
    const DenseSystem d = make_system(40, 5, seed, [](double t, int c, double r) { return -0.4 + 1.8 * r + 0.1 * t * c; });
    const BoxQpResult qp = solve_box_constrained(equations_of(d));
    for (int c = 0; c < 4; ++c) {
      double best = 0.0;
      const Eigen::VectorXd ref = exhaustive_box_lsq(d.s, d.b.col(c), &best);
      // S has full column rank here (40 random rows), so the minimizer is unique; both are
      // direct solves of small well-conditioned systems: 1e-9 covers rounding with margin.
      EXPECT_NEAR(objective(d, qp.x, c), best, 1e-9 * (1.0 + best)) << "channel " << c;
      EXPECT_LT((qp.x.col(c) - ref).cwiseAbs().maxCoeff(), 1e-9) << "channel " << c;
      EXPECT_TRUE(qp.channels[size_t(c)].converged);
      EXPECT_LT(qp.channels[size_t(c)].kkt, 1e-12);
    }
  }
}

TEST(BoxQp, MediumProblemMatchesLongProjectedGradient) {
  const DenseSystem d = make_system(3000, 24, 7, [](double t, int c, double r) {
    return step_colour(t, c, r) * 0.9 + 0.1 * r;  // steps plus noise: active and inactive bounds
  });
  const BoxQpResult qp = solve_box_constrained(equations_of(d));
  uint32_t active = 0;
  for (int c = 0; c < 4; ++c) {
    const Eigen::VectorXd ref = projected_gradient_box_lsq(d.s, d.b.col(c), 4000);
    // FISTA converges as O(1/k^2) in the objective and linearly here (M is well conditioned:
    // uniform coordinates); 4000 iterations reach rounding level, 1e-8 leaves margin.
    EXPECT_LT((qp.x.col(c) - ref).cwiseAbs().maxCoeff(), 1e-8) << "channel " << c;
    active += qp.channels[size_t(c)].at_lower + qp.channels[size_t(c)].at_upper;
  }
  EXPECT_GT(active, 0u) << "the case should have active bounds";
}

TEST(BoxQp, InactiveConstraintsGiveTheNormalEquationsSolution) {
  const DenseSystem d = make_system(2000, 32, 3, smooth_colour);
  const NormalEquations eq = equations_of(d);
  const BoxQpResult qp = solve_box_constrained(eq);
  const SolveResult ne = solve_normal_equations(eq);
  ASSERT_EQ(ne.clamped_values, 0u);
  for (int c = 0; c < 4; ++c) {
    EXPECT_EQ(qp.channels[size_t(c)].at_lower + qp.channels[size_t(c)].at_upper, 0u);
    // Both solve the same tridiagonal system directly (cond(M) ~ 10): agreement to rounding.
    EXPECT_LT((qp.x.col(c) - ne.x.col(c)).cwiseAbs().maxCoeff(), 1e-12);
  }
}

// A clamp by rounding (a TF's zeros fitted exactly) is counted but not said; one that matters is
// said with how far it moved. M = I, so x = the right-hand side.
TEST(BoxQp, OnlyClampsThatMatterAreWarnedOf) {
  for (const double below : {-1e-9, -0.02}) {
    NormalEquations eq(3);
    for (uint32_t j = 0; j < 3; ++j) eq.diag[j] = 1.0;
    eq.rhs.setConstant(0.5);
    eq.rhs(1, 3) = below;
    eq.voxels = 3;
    const SolveResult ne = solve_normal_equations(eq);
    EXPECT_EQ(ne.clamped_values, 1u) << below;
    EXPECT_EQ(ne.tf.rgba[1][3], 0.0) << below;
    if (below > -kClampWarnDistance) {
      EXPECT_TRUE(ne.warnings.empty()) << ne.warnings[0];
    } else {
      ASSERT_EQ(ne.warnings.size(), 1u);
      EXPECT_EQ(ne.warnings[0].find("1 TF component fell outside [0,1] and was clamped (by up to 0.02); "), 0u)
          << ne.warnings[0];
    }
  }
}

TEST(BoxQp, ActiveConstraintsBeatClampingAndSatisfyKkt) {
  const DenseSystem d = make_system(2000, 16, 5, step_colour);
  const NormalEquations eq = equations_of(d);
  const SolveResult ne = solve_normal_equations(eq);
  ASSERT_GT(ne.clamped_values, 0u) << "the step should push the unconstrained fit out of [0,1]";
  const std::string said = std::to_string(ne.clamped_values) +
                          (ne.clamped_values == 1 ? " TF component fell outside [0,1] and was clamped"
                                                  : " TF components fell outside [0,1] and were clamped");
  ASSERT_EQ(ne.warnings.size(), 1u);
  EXPECT_EQ(ne.warnings[0].find(said), 0u) << ne.warnings[0];
  const BoxQpResult qp = solve_box_constrained(eq);
  const Tridiagonal h = regularized_matrix(eq, {});
  double clamped_total = 0.0, qp_total = 0.0;
  for (int c = 0; c < 4; ++c) {
    Eigen::VectorXd clamped = ne.x.col(c).cwiseMax(0.0).cwiseMin(1.0);
    EXPECT_LT(qp.channels[size_t(c)].kkt, 1e-12);
    // Clamping is not optimal once bounds are active: its KKT residual is far from 0.
    EXPECT_GT(box_kkt_residual(h, eq.rhs.col(c), clamped), 1e-3) << "channel " << c;
    clamped_total += (d.s * clamped - d.b.col(c)).squaredNorm();
    qp_total += objective(d, qp.x, c);
  }
  EXPECT_LT(qp_total, clamped_total);
}

TEST(BoxQp, KktResidualDetectsNonOptimalPoints) {
  const DenseSystem d = make_system(500, 8, 9, smooth_colour);
  const NormalEquations eq = equations_of(d);
  const BoxQpResult qp = solve_box_constrained(eq);
  const Tridiagonal h = regularized_matrix(eq, {});
  Eigen::VectorXd x = qp.x.col(0);
  ASSERT_LT(box_kkt_residual(h, eq.rhs.col(0), x), 1e-12);
  x[3] += 1e-4;
  EXPECT_GT(box_kkt_residual(h, eq.rhs.col(0), x), 1e-5);
  x[3] = 1.5;  // outside the box
  EXPECT_GE(box_kkt_residual(h, eq.rhs.col(0), x), 0.5);
}

// Under heavy smoothing H is ill-conditioned: a point off the optimum along a smooth direction
// leaves a gradient of about lambda_min times its distance, while H_jj is near lambda_max. The
// residual (a Newton step on the free components) must read the distance; the diagonal step it
// replaced read 1e-7 for the 0.1 here (and gradient descent in `tfmatch solvers` at --smooth 1e6
// stood 0.63 from the optimum with a "KKT" of 6e-6).
TEST(BoxQp, KktResidualReadsTheDistanceUnderHeavySmoothing) {
  const DenseSystem d = make_system(3000, 64, 13, smooth_colour);
  const NormalEquations eq = equations_of(d);
  SolveOptions options;
  options.smooth = 1e6;
  const Tridiagonal h = regularized_matrix(eq, absolute_regularization(eq, options));
  const BoxQpResult qp = solve_box_constrained(eq, options);
  const Eigen::VectorXd c = eq.rhs.col(0);
  Eigen::VectorXd x = qp.x.col(0);
  ASSERT_LT(box_kkt_residual(h, c, x), 1e-9);
  ASSERT_GT(x.minCoeff(), 0.15);
  ASSERT_LT(x.maxCoeff(), 0.85);
  // The smoothest direction: every entry 0.1 higher, inside the box.
  x.array() += 0.1;
  const double residual = box_kkt_residual(h, c, x);
  EXPECT_GT(residual, 0.09);
  EXPECT_LT(residual, 0.11);
  Eigen::VectorXd g = -c;  // H x - c, for the diagonal step
  for (Eigen::Index j = 0; j < x.size(); ++j) {
    g[j] += h.diag[size_t(j)] * x[j];
    if (j > 0) g[j] += h.off[size_t(j - 1)] * x[j - 1];
    if (j + 1 < x.size()) g[j] += h.off[size_t(j)] * x[j + 1];
  }
  double diagonal_step = 0.0;
  for (Eigen::Index j = 0; j < x.size(); ++j)
    diagonal_step = std::max(diagonal_step, std::abs(g[j] / h.diag[size_t(j)]));
  EXPECT_LT(diagonal_step, 1e-5) << "the diagonal step should read small here (else the test shows nothing)";
  // On a bound with the multiplier's sign wrong, the component is free and the step moves it in.
  Eigen::VectorXd low = qp.x.col(0);
  low[10] = 0.0;
  EXPECT_GT(box_kkt_residual(h, c, low), 0.1);
}

TEST(BoxQp, UnreferencedEntriesStayZeroWithoutNaN) {
  // Voxels only in cells [0, 4) and [9, 15): entries 5..8 are touched by no voxel (zero rows of M).
  DenseSystem a = make_system(300, 16, 11, step_colour, 0, 4);
  const DenseSystem b = make_system(300, 16, 12, step_colour, 9, 15);
  DenseSystem d{Eigen::MatrixXd(600, 16), Eigen::MatrixX4d(600, 4)};
  d.s << a.s, b.s;
  d.b << a.b, b.b;
  const NormalEquations eq = equations_of(d);
  ASSERT_EQ(eq.diag[6], 0.0);
  const BoxQpResult plain = solve_box_constrained(eq);
  EXPECT_TRUE(plain.x.allFinite());
  for (int c = 0; c < 4; ++c) {
    for (int j = 5; j <= 8; ++j) EXPECT_EQ(plain.x(j, c), 0.0) << "entry " << j;
    EXPECT_LT(plain.channels[size_t(c)].kkt, 1e-12);
  }
  // Smoothness fills the gap from the neighbours: finite, inside the box, optimal for M + R.
  SolveOptions smooth;
  smooth.smooth = 0.05;
  const BoxQpResult reg = solve_box_constrained(eq, smooth);
  EXPECT_TRUE(reg.x.allFinite());
  for (int c = 0; c < 4; ++c) EXPECT_LT(reg.channels[size_t(c)].kkt, 1e-12);
  EXPECT_GT(reg.x.block(5, 0, 4, 4).cwiseAbs().maxCoeff(), 0.0);
  // Ridge: the exhaustive reference on the augmented system [S; sqrt(ridge) I].
  SolveOptions ridge;
  ridge.ridge = 0.01;
  const BoxQpResult rr = solve_box_constrained(eq, ridge);
  const Regularization abs = absolute_regularization(eq, ridge);
  Eigen::MatrixXd s_aug(600 + 16, 16);
  s_aug << d.s, std::sqrt(abs.ridge) * Eigen::MatrixXd::Identity(16, 16);
  const Eigen::VectorXd x_ref = projected_gradient_box_lsq(s_aug, (Eigen::VectorXd(616) << d.b.col(0), Eigen::VectorXd::Zero(16)).finished(), 20000);
  // The ridge makes M + R well conditioned (cond < 1e3): FISTA reaches rounding level.
  EXPECT_LT((rr.x.col(0) - x_ref).cwiseAbs().maxCoeff(), 1e-8);
}

TEST(BoxQp, SingularBlockWithReferencedEntriesGivesAMinimizer) {
  // Every voxel at the same w in its cell: each cell's two entries are tied by one equation, so
  // M has a null direction per cell although no diagonal entry is 0.
  const uint32_t n = 4;
  DenseSystem d{Eigen::MatrixXd::Zero(30, n), Eigen::MatrixX4d(30, 4)};
  std::mt19937 rng(5);
  for (int i = 0; i < 30; ++i) {
    const uint32_t j = (i % 2) * 2;  // cells 0 and 2 only: entries (0,1) and (2,3)
    d.s(i, j) = 0.75;
    d.s(i, j + 1) = 0.25;
    for (int c = 0; c < 4; ++c) d.b(i, c) = -0.5 + 2.0 * double(rng() % 100) / 100.0;
  }
  const NormalEquations eq = equations_of(d);
  const BoxQpResult qp = solve_box_constrained(eq);
  ASSERT_TRUE(qp.x.allFinite());
  for (int c = 0; c < 4; ++c) {
    double best = 0.0;
    exhaustive_box_lsq(d.s, d.b.col(c), &best);
    // Minimizers are not unique; their objective is. Rounding of a singular solve: 1e-9.
    EXPECT_NEAR(objective(d, qp.x, c), best, 1e-9 * (1.0 + best)) << "channel " << c;
    EXPECT_TRUE(qp.channels[size_t(c)].converged);
  }
}

TEST(BoxQp, IterationCapIsReported) {
  const DenseSystem d = make_system(2000, 16, 5, step_colour);
  BoxQpOptions o;
  o.max_iterations = 1;
  const BoxQpResult qp = solve_box_constrained(equations_of(d), {}, o);
  EXPECT_FALSE(qp.warnings.empty());
  EXPECT_TRUE(qp.x.allFinite());
  EXPECT_TRUE((qp.x.array() >= 0.0).all() && (qp.x.array() <= 1.0).all());
}

TEST(BoxQp, RejectsBadInput) {
  NormalEquations empty(8);
  EXPECT_THROW(solve_box_constrained(empty), std::runtime_error);  // no voxels
  Tridiagonal h{{1.0, 1.0}, {0.0}};
  Eigen::VectorXd c(3), x(3);
  EXPECT_THROW(solve_box_qp(h, c, x), std::invalid_argument);
}

}  // namespace
}  // namespace tfm
