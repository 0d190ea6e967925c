// CPU reference assembly and the host solver of the tridiagonal normal equations.
#include "normal_equations.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

namespace tfm {

Eigen::VectorXd tridiagonal_eigenvalues(const std::vector<double>& diag, const std::vector<double>& off) {
  Eigen::VectorXd d = Eigen::Map<const Eigen::VectorXd>(diag.data(), Eigen::Index(diag.size()));
  Eigen::VectorXd e = Eigen::Map<const Eigen::VectorXd>(off.data(), Eigen::Index(off.size()));
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver;
  solver.computeFromTridiagonal(d, e, Eigen::EigenvaluesOnly);
  if (solver.info() != Eigen::Success) throw std::runtime_error("eigenvalues of M did not converge");
  return solver.eigenvalues();
}

Regularization absolute_regularization(const NormalEquations& eq, const SolveOptions& options) {
  double mean_diag = 0.0;
  for (double d : eq.diag) mean_diag += d;
  if (eq.n > 0) mean_diag /= eq.n;
  return {options.ridge * mean_diag, options.smooth * mean_diag};
}

Tridiagonal regularized_matrix(const NormalEquations& eq, const Regularization& r) {
  const uint32_t n = eq.n;
  Tridiagonal t{eq.diag, eq.off};
  for (uint32_t j = 0; j < n; ++j) t.diag[j] += r.ridge + r.smooth * ((j == 0 || j == n - 1) ? 1.0 : 2.0);
  for (uint32_t j = 0; j + 1 < n; ++j) t.off[j] -= r.smooth;
  return t;
}

SolveResult solve_normal_equations(const NormalEquations& eq, const SolveOptions& options) {
  const uint32_t n = eq.n;
  if (n < 2) throw std::invalid_argument("transfer functions need at least 2 entries");
  if (eq.voxels == 0)
    throw std::runtime_error("no voxel has data in both fields (all NaN?): nothing to fit");
  if (options.ridge < 0 || options.smooth < 0) throw std::invalid_argument("regularization weights must be >= 0");

  SolveResult result;
  for (uint32_t j = 0; j < n; ++j) result.unreferenced_entries += eq.diag[j] == 0.0 ? 1 : 0;

  // Regularized tridiagonal matrix: M + ridge I + smooth D^T D (first differences), both scaled
  // by mean(diag M) so they keep their meaning across volume sizes.
  Tridiagonal reg = regularized_matrix(eq, absolute_regularization(eq, options));
  const std::vector<double>& d = reg.diag;
  const std::vector<double>& e = reg.off;

  Eigen::VectorXd lambda = tridiagonal_eigenvalues(d, e);
  result.lambda_min = lambda(0);
  result.lambda_max = lambda(n - 1);
  // M is positive semi-definite; rounding can make a zero eigenvalue slightly negative.
  const double singular_tol = 1e-12 * std::abs(result.lambda_max);
  const bool singular = result.lambda_min <= singular_tol;
  result.cond = singular ? std::numeric_limits<double>::infinity() : result.lambda_max / result.lambda_min;

  Factorization f = options.factorization;
  if (f == Factorization::Auto) f = singular ? Factorization::QR : Factorization::LDLT;

  if (f == Factorization::LDLT) {
    Eigen::SparseMatrix<double> m(n, n);
    std::vector<Eigen::Triplet<double>> t;
    for (uint32_t j = 0; j < n; ++j) t.emplace_back(j, j, d[j]);
    for (uint32_t j = 0; j + 1 < n; ++j) t.emplace_back(j + 1, j, e[j]), t.emplace_back(j, j + 1, e[j]);
    m.setFromTriplets(t.begin(), t.end());
    // Natural ordering keeps the tridiagonal band: no fill-in, O(N) factorization.
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::NaturalOrdering<int>> ldlt(m);
    if (ldlt.info() != Eigen::Success) throw std::runtime_error("LDL^T factorization of M failed");
    result.x = ldlt.solve(eq.rhs);
    result.factorization = "ldlt";
    if (!result.x.allFinite()) {
      // A singular M the LDL^T could not pivot around: fall back to the rank-revealing QR.
      f = Factorization::QR;
      result.warnings.push_back("LDL^T produced non-finite values; used column-pivoted QR instead");
    }
  }
  if (f == Factorization::QR) {
    Eigen::MatrixXd m = Eigen::MatrixXd::Zero(n, n);
    for (uint32_t j = 0; j < n; ++j) m(j, j) = d[j];
    for (uint32_t j = 0; j + 1 < n; ++j) m(j, j + 1) = m(j + 1, j) = e[j];
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(m);
    // Directions below this relative size carry no information from the data: their
    // components of x are set to 0 (the basic solution).
    qr.setThreshold(1e-10);
    result.x = qr.solve(eq.rhs);
    result.factorization = "column-pivoted-qr";
  }

  if (singular && options.ridge == 0 && options.smooth == 0) {
    std::ostringstream os;
    os << "M is singular: " << result.unreferenced_entries
       << " TF entries are touched by no voxel and were set to 0; --smooth fills them from their neighbours";
    result.warnings.push_back(os.str());
  } else if (result.cond > options.cond_warning) {
    std::ostringstream os;
    os << "cond(M) = " << result.cond << " exceeds " << options.cond_warning
       << ": M carries ~1e-7 relative error from float32 data, so x may be wrong by cond*1e-7; "
          "consider --solver cgls or --smooth";
    result.warnings.push_back(os.str());
  }

  result.tf.rgba.resize(n);
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) {
      double v = result.x(j, c);
      double clamped = std::clamp(v, 0.0, 1.0);
      if (clamped != v) ++result.clamped_values;
      result.tf.rgba[j][c] = clamped;
    }
  if (result.clamped_values > 0) {
    std::ostringstream os;
    os << result.clamped_values << " TF components fell outside [0,1] and were clamped; "
       << "--solver qp gives the exact box-constrained optimum";
    result.warnings.push_back(os.str());
  }
  return result;
}

}  // namespace tfm
