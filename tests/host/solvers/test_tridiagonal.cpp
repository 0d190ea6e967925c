// The O(N) tridiagonal solves and eigenvalues (host/solvers/tridiagonal.h) against dense Eigen on
// small N: full-rank systems, exactly singular ones (unreferenced entries, runs of single-valued
// cells, both), float32-rounded near-singular ones, long runs whose null vector grows
// geometrically; and the box-constrained solver on the same singular structure.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Dense>

#include "tfmatch/solvers/box_qp.h"
#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/tridiagonal.h"

namespace tfm {
namespace {

// An explicit voxel system: S (voxels x n, rows (1-w) at j and w at j+1) and b (voxels x 4).
struct Voxels {
  uint32_t n = 0;
  std::vector<std::pair<uint32_t, double>> cells;  // (j, w) per voxel
  Eigen::MatrixXd s() const {
    Eigen::MatrixXd m = Eigen::MatrixXd::Zero(Eigen::Index(cells.size()), n);
    for (size_t i = 0; i < cells.size(); ++i) {
      m(Eigen::Index(i), cells[i].first) = 1.0 - cells[i].second;
      m(Eigen::Index(i), cells[i].first + 1) = cells[i].second;
    }
    return m;
  }
};

// M = S^T S as the tridiagonal solver takes it.
Tridiagonal gram(const Eigen::MatrixXd& s) {
  const Eigen::MatrixXd m = s.transpose() * s;
  Tridiagonal t;
  for (Eigen::Index j = 0; j < m.rows(); ++j) t.diag.push_back(m(j, j));
  for (Eigen::Index j = 0; j + 1 < m.rows(); ++j) t.off.push_back(m(j, j + 1));
  return t;
}

Eigen::MatrixXd random_b(size_t rows, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Eigen::MatrixXd b(Eigen::Index(rows), 4);
  for (Eigen::Index i = 0; i < b.rows(); ++i)
    for (int c = 0; c < 4; ++c) b(i, c) = u(rng);
  return b;
}

// The independent reference: minimum-norm least squares on the explicit S (complete orthogonal
// decomposition of S itself; no normal equations).
Eigen::MatrixXd dense_min_norm(const Eigen::MatrixXd& s, const Eigen::MatrixXd& b) {
  return s.completeOrthogonalDecomposition().solve(b);
}

double max_abs(const Eigen::MatrixXd& m) { return m.cwiseAbs().maxCoeff(); }

// Cells with w on multiples of 1/8, so that every product in M is exact in double: singular
// systems stay exactly singular.
std::pair<uint32_t, double> dyadic_cell(std::mt19937& rng, uint32_t first, uint32_t last) {
  return {first + uint32_t(rng() % (last - first)), double(rng() % 8) / 8.0};
}

TEST(Tridiagonal, FullRankMatchesDenseLeastSquares) {
  for (uint32_t n : {2u, 3u, 13u, 127u}) {
    std::mt19937 rng(n);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    Voxels v{n, {}};
    for (uint32_t k = 0; k < 6 * n; ++k) v.cells.push_back({uint32_t(rng() % (n - 1)), u(rng)});
    const Eigen::MatrixXd s = v.s(), b = random_b(v.cells.size(), n + 1);
    const Tridiagonal t = gram(s);
    const Eigen::MatrixXd rhs = s.transpose() * b;
    const MinNormSolve solved = solve_psd_tridiagonal_min_norm(t, rhs);
    const Eigen::MatrixXd expected = dense_min_norm(s, b);
    EXPECT_EQ(solved.unreferenced + solved.dependent, 0u) << "n=" << n;
    // cond(M) stays below 1e4 for these draws, so 1e-10 is rounding times cond with room.
    EXPECT_LE(max_abs(solved.x - expected), 1e-10 * std::max(1.0, max_abs(expected))) << "n=" << n;
    EXPECT_LE(max_abs(solve_tridiagonal_ldlt(t, rhs) - expected), 1e-10 * std::max(1.0, max_abs(expected)));
  }
}

// Exactly singular M of every kind the assembly produces: entries no voxel touches (zero rows),
// runs of cells holding one weight each (one null vector per run, no zero row), both together,
// and a single voxel on a node (w = 0: the next entry is untouched).
TEST(Tridiagonal, SingularSystemsGiveTheMinimumNormSolution) {
  struct Case {
    const char* name;
    uint32_t n;
    std::vector<std::pair<uint32_t, double>> cells;
  };
  std::vector<Case> cases = {
      {"one voxel, N = 2", 2, {{0, 0.5}}},
      {"one voxel on a node", 3, {{1, 0.0}}},
      {"chain of single weights", 6, {{0, 0.25}, {1, 0.5}, {2, 0.75}, {3, 0.125}, {4, 0.5}}},
      {"chain, unreferenced tail", 8, {{0, 0.25}, {0, 0.25}, {1, 0.625}, {2, 0.5}}},
      {"two chains and a gap", 9, {{0, 0.5}, {1, 0.25}, {4, 0.75}, {5, 0.5}, {6, 0.375}, {7, 0.875}}},
  };
  // Random mixtures: some cells with several weights (full rank there), some with one, gaps.
  std::mt19937 rng(7);
  for (uint32_t k = 0; k < 6; ++k) {
    Case c{"random mixture", 12 + 5 * k, {}};
    for (uint32_t i = 0; i < c.n / 2; ++i) c.cells.push_back(dyadic_cell(rng, 0, c.n - 1));
    c.cells.push_back({c.n - 2, 0.5});
    cases.push_back(c);
  }
  for (const Case& c : cases) {
    const Voxels v{c.n, c.cells};
    const Eigen::MatrixXd s = v.s(), b = random_b(v.cells.size(), c.n);
    const Tridiagonal t = gram(s);
    const MinNormSolve solved = solve_psd_tridiagonal_min_norm(t, s.transpose() * b);
    const Eigen::MatrixXd expected = dense_min_norm(s, b);
    ASSERT_TRUE(solved.x.allFinite()) << c.name;
    EXPECT_GT(solved.unreferenced + solved.dependent, 0u) << c.name << ": the case is singular";
    EXPECT_LE(max_abs(solved.x - expected), 1e-9 * std::max(1.0, max_abs(expected)))
        << c.name << "\nexpected\n" << expected.transpose() << "\ngot\n" << solved.x.transpose();
  }
}

// The normal-equations solver on a singular system: same minimum-norm solution, the counts and
// the warning; cond is infinite; --factorization ldlt falls back with a warning.
TEST(Tridiagonal, NormalEquationsSolverReportsSingularSystems) {
  const Voxels v{7, {{0, 0.25}, {1, 0.5}, {2, 0.75}, {4, 0.5}}};
  const Eigen::MatrixXd s = v.s(), b = random_b(v.cells.size(), 3);
  const Tridiagonal t = gram(s);
  NormalEquations eq(7);
  eq.diag = t.diag;
  eq.off = t.off;
  eq.rhs = s.transpose() * b;
  eq.voxels = v.cells.size();
  for (Factorization f : {Factorization::Auto, Factorization::LDLT}) {
    SolveOptions options;
    options.factorization = f;
    const SolveResult r = solve_normal_equations(eq, options);
    EXPECT_EQ(r.factorization, "min-norm-ldlt");
    EXPECT_TRUE(std::isinf(r.cond));
    EXPECT_EQ(r.unreferenced_entries, 1u);  // entry 6
    EXPECT_GE(r.dependent_entries, 1u);
    EXPECT_LE(max_abs(r.x - dense_min_norm(s, b)), 1e-9);
    bool warned = false;
    for (const std::string& w : r.warnings) warned |= w.find("M is singular") != std::string::npos;
    EXPECT_TRUE(warned);
  }
}

// Weights computed in float32, as the GPU assembly computes its products: runs of single-weight
// cells are singular only up to float rounding (pivots ~1e-7 of the diagonal). The solve must
// still give a least-squares solution (the dense optimum's objective) with bounded values, where
// plain LDL^T divides by rounding noise.
TEST(Tridiagonal, Float32RoundedSingularRunsStayBounded) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const uint32_t n = 200;
  Voxels v{n, {}};
  for (uint32_t j = 0; j + 1 < n; ++j)
    if (j % 17 != 16) v.cells.push_back({j, double(u(rng))});  // one voxel per cell, a gap now and then
  const Eigen::MatrixXd s = v.s(), b = random_b(v.cells.size(), 5);
  Tridiagonal t = gram(s);
  // Round every entry of M and S^T b to float32, like the products the assembly sums.
  for (double& x : t.diag) x = double(float(x));
  for (double& x : t.off) x = double(float(x));
  Eigen::MatrixXd rhs = s.transpose() * b;
  for (Eigen::Index i = 0; i < rhs.size(); ++i) rhs.data()[i] = double(float(rhs.data()[i]));
  const MinNormSolve solved = solve_psd_tridiagonal_min_norm(t, rhs);
  const Eigen::MatrixXd expected = dense_min_norm(s, b);
  EXPECT_GE(solved.dependent, 1u);
  ASSERT_TRUE(solved.x.allFinite());
  // Every column's objective within float32 noise of the optimum, and no value blown up past
  // the minimum-norm solution's size by more than the noise allows.
  for (int c = 0; c < 4; ++c) {
    const double best = (s * expected.col(c) - b.col(c)).squaredNorm();
    const double got = (s * solved.x.col(c) - b.col(c)).squaredNorm();
    EXPECT_LE(got, best + 1e-4 * b.col(c).squaredNorm()) << "channel " << c;
  }
  EXPECT_LE(max_abs(solved.x), 2.0 * max_abs(expected) + 0.1);
}

// A run of 200000 cells with weight 3/4 each: the null vector grows by 1/3 per entry (3^-200000
// overall), far past double range. The solve rescales it as it goes: finite values, the system
// solved, and x orthogonal to the null vector (checked in logarithms).
TEST(Tridiagonal, LongRunsNeitherOverflowNorLoseTheSolution) {
  const uint32_t n = 200001;
  Tridiagonal t;
  t.diag.assign(n, 0.0);
  t.off.assign(n - 1, 0.0);
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n, 1);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double w = 0.75;
  std::vector<double> b(n - 1);
  for (uint32_t j = 0; j + 1 < n; ++j) {
    t.diag[j] += (1 - w) * (1 - w);
    t.diag[j + 1] += w * w;
    t.off[j] += (1 - w) * w;
    b[j] = u(rng);
    rhs(j, 0) += (1 - w) * b[j];
    rhs(j + 1, 0) += w * b[j];
  }
  const MinNormSolve solved = solve_psd_tridiagonal_min_norm(t, rhs);
  ASSERT_TRUE(solved.x.allFinite());
  EXPECT_EQ(solved.dependent, 1u);
  // Each voxel's equation (1-w) x_j + w x_{j+1} = b_j holds: the system is consistent.
  double worst = 0;
  for (uint32_t j = 0; j + 1 < n; ++j)
    worst = std::max(worst, std::abs((1 - w) * solved.x(j, 0) + w * solved.x(j + 1, 0) - b[j]));
  EXPECT_LE(worst, 1e-9);
  // Null vector z_j = (-(1-w)/w)^j = (-1/3)^j: sum z_j x_j = 0. Terms past j = 40 are below 1e-19.
  double dot = 0, zz = 0;
  for (uint32_t j = 0; j < 60; ++j) {
    const double z = std::pow(-(1 - w) / w, double(j));
    dot += z * solved.x(j, 0);
    zz += z * z;
  }
  EXPECT_LE(std::abs(dot) / std::sqrt(zz), 1e-9);
}

TEST(Tridiagonal, ExtremeEigenvaluesMatchDense) {
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  for (uint32_t n : {1u, 2u, 13u, 127u, 300u}) {
    for (int kind = 0; kind < 3; ++kind) {
      Tridiagonal t;
      for (uint32_t j = 0; j < n; ++j) t.diag.push_back(kind == 0 ? g(rng) : 4.0 + g(rng) * 0.5);
      for (uint32_t j = 0; j + 1 < n; ++j) t.off.push_back(kind == 2 && j % 5 == 0 ? 0.0 : g(rng));
      Eigen::MatrixXd m = Eigen::MatrixXd::Zero(n, n);
      for (uint32_t j = 0; j < n; ++j) m(j, j) = t.diag[j];
      for (uint32_t j = 0; j + 1 < n; ++j) m(j, j + 1) = m(j + 1, j) = t.off[j];
      const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m).eigenvalues();
      const auto [lo, hi] = tridiagonal_extreme_eigenvalues(t);
      const double scale = std::max(std::abs(ev(0)), std::abs(ev(n - 1)));
      EXPECT_NEAR(lo, ev(0), 1e-13 * scale) << "n=" << n << " kind " << kind;
      EXPECT_NEAR(hi, ev(n - 1), 1e-13 * scale) << "n=" << n << " kind " << kind;
    }
  }
  // A singular PSD matrix: the smallest eigenvalue is 0 to roundoff of the norm.
  const Voxels v{6, {{0, 0.25}, {1, 0.5}, {2, 0.75}, {3, 0.5}, {4, 0.5}}};
  const auto [lo, hi] = tridiagonal_extreme_eigenvalues(gram(v.s()));
  EXPECT_LE(std::abs(lo), 1e-14 * hi);
}

TEST(Tridiagonal, RejectsMismatchedSizes) {
  Tridiagonal t{{1.0, 1.0}, {0.5}};
  EXPECT_THROW(solve_psd_tridiagonal_min_norm(t, Eigen::MatrixXd::Zero(3, 1)), std::invalid_argument);
  t.off.push_back(0.0);
  EXPECT_THROW(solve_tridiagonal_ldlt(t, Eigen::MatrixXd::Zero(2, 1)), std::invalid_argument);
  EXPECT_THROW(tridiagonal_extreme_eigenvalues(Tridiagonal{}), std::invalid_argument);
}

// L D L^T of positive definite matrices (the cgls preconditioner's diag(M) + s D^T D, heavy and
// light smoothing, and a random diagonally dominant one) multiplies back to T within roundoff; an
// indefinite or singular matrix and mismatched sizes are refused.
TEST(Tridiagonal, PositiveDefiniteFactorsMultiplyBack) {
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const uint32_t n = 37;
  for (const double smooth : {0.0, 1e-3, 1.0, 1e8}) {
    Tridiagonal t;
    for (uint32_t j = 0; j < n; ++j) t.diag.push_back(31.0 + 100.0 * u(rng) + smooth * ((j > 0) + (j + 1 < n)));
    for (uint32_t j = 0; j + 1 < n; ++j) t.off.push_back(smooth > 0.0 ? -smooth : 30.0 * (u(rng) - 0.5));
    const TridiagonalLdlt f = factor_positive_definite(t);
    ASSERT_EQ(f.pivot.size(), n);
    ASSERT_EQ(f.lower.size(), n - 1);
    Eigen::MatrixXd l = Eigen::MatrixXd::Identity(n, n), dense = Eigen::MatrixXd::Zero(n, n);
    for (uint32_t j = 0; j + 1 < n; ++j) l(j + 1, j) = f.lower[j];
    for (uint32_t j = 0; j < n; ++j) {
      EXPECT_GT(f.pivot[j], 0.0);
      dense(j, j) = t.diag[j];
      if (j + 1 < n) dense(j, j + 1) = dense(j + 1, j) = t.off[j];
    }
    const Eigen::MatrixXd back = l * Eigen::VectorXd::Map(f.pivot.data(), n).asDiagonal() * l.transpose();
    EXPECT_LE(max_abs(back - dense), 1e-14 * max_abs(dense)) << "smooth " << smooth;
  }
  EXPECT_THROW(factor_positive_definite(Tridiagonal{{1.0, 1.0}, {1.0}}), std::invalid_argument);   // singular
  EXPECT_THROW(factor_positive_definite(Tridiagonal{{1.0, -2.0}, {0.5}}), std::invalid_argument);  // indefinite
  EXPECT_THROW(factor_positive_definite(Tridiagonal{{1.0, 1.0}, {}}), std::invalid_argument);
}

// The box-constrained solver on runs of single-weight cells (singular without zero rows),
// against exhaustive enumeration of active sets on the explicit S for N = 6.
TEST(Tridiagonal, BoxConstrainedSingularRunsMatchEnumeration) {
  const Voxels v{6, {{0, 0.25}, {1, 0.5}, {1, 0.5}, {3, 0.75}, {4, 0.375}}};
  const Eigen::MatrixXd s = v.s();
  Eigen::MatrixXd b(Eigen::Index(v.cells.size()), 1);
  b << 1.3, -0.2, -0.2, 0.9, 0.4;  // outside [0,1] in places: bounds become active
  const Tridiagonal t = gram(s);
  const Eigen::VectorXd c = s.transpose() * b.col(0);
  Eigen::VectorXd x = solve_psd_tridiagonal_min_norm(t, c).x.col(0);
  const BoxQpStats stats = solve_box_qp(t, c, x);
  EXPECT_TRUE(stats.converged);
  // Exhaustive: each component at 0, at 1 or free (free part by dense minimum-norm least
  // squares); the best feasible objective.
  double best = INFINITY;
  for (int code = 0; code < 729; ++code) {
    Eigen::VectorXd y = Eigen::VectorXd::Zero(6);
    std::vector<Eigen::Index> free;
    for (int j = 0, k = code; j < 6; ++j, k /= 3) {
      if (k % 3 == 1) y[j] = 1.0;
      if (k % 3 == 2) free.push_back(j);
    }
    if (!free.empty()) {
      Eigen::MatrixXd sf(s.rows(), Eigen::Index(free.size()));
      for (size_t f = 0; f < free.size(); ++f) sf.col(Eigen::Index(f)) = s.col(free[f]);
      const Eigen::VectorXd yf = sf.completeOrthogonalDecomposition().solve(b.col(0) - s * y);
      if ((yf.array() < -1e-12).any() || (yf.array() > 1 + 1e-12).any()) continue;
      for (size_t f = 0; f < free.size(); ++f) y[free[f]] = yf[Eigen::Index(f)];
    }
    best = std::min(best, (s * y - b.col(0)).squaredNorm());
  }
  EXPECT_NEAR((s * x - b.col(0)).squaredNorm(), best, 1e-12);
  EXPECT_LE(stats.kkt, 1e-12);
}

}  // namespace
}  // namespace tfm
