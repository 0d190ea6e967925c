// Preconditioned CGLS on an explicit sparse matrix, in double.
#include "tfmatch/solvers/cgls_cpu.h"

#include <cmath>
#include <stdexcept>

#include "tfmatch/model/cancellation.h"

namespace tfm {

CglsResult cgls_preconditioned(const Eigen::SparseMatrix<double, Eigen::RowMajor>& a, const Eigen::VectorXd& b,
                               const Eigen::SparseMatrix<double>& r, const CglsPreconditionerFn& inverse,
                               const CglsOptions& options) {
  const Eigen::Index n = a.cols();
  const bool regularized = r.nonZeros() > 0;
  if (b.size() != a.rows() || (regularized && (r.rows() != n || r.cols() != n)))
    throw std::invalid_argument("cgls: sizes of A, b and R do not match");

  CglsResult out;
  out.x = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd res = b;                      // r = b - A x
  Eigen::VectorXd s = a.transpose() * res;      // s = A^T r - R x
  const double s0 = s.norm();
  if (s0 == 0.0) {
    out.converged = true;
    return out;
  }
  Eigen::VectorXd z = inverse(s);
  Eigen::VectorXd p = z;
  double gamma = s.dot(z);
  Eigen::VectorXd q, rp;
  out.relative_residual = 1.0;
  while (out.iterations < options.max_iterations && out.relative_residual > options.tolerance) {
    checkpoint("solve");
    q = a * p;
    double delta = q.squaredNorm();
    if (regularized) {
      rp = r * p;
      delta += p.dot(rp);
    }
    if (!(delta > 0.0)) break;  // p in the null space: nothing more to gain
    const double alpha = gamma / delta;
    out.x += alpha * p;
    res -= alpha * q;
    s = a.transpose() * res;
    if (regularized) s -= r * out.x;
    z = inverse(s);
    const double gamma_new = s.dot(z);
    p = z + (gamma_new / gamma) * p;
    gamma = gamma_new;
    ++out.iterations;
    out.relative_residual = s.norm() / s0;
    if (!(gamma > 0.0)) break;
  }
  out.converged = out.relative_residual <= options.tolerance;
  return out;
}

CglsResult cgls_jacobi(const Eigen::SparseMatrix<double, Eigen::RowMajor>& a, const Eigen::VectorXd& b,
                       const Eigen::SparseMatrix<double>& r, const CglsOptions& options) {
  const Eigen::Index n = a.cols();
  if (r.nonZeros() > 0 && (r.rows() != n || r.cols() != n))
    throw std::invalid_argument("cgls_jacobi: sizes of A, b and R do not match");
  // Jacobi: squared column norms of A plus the diagonal of R.
  Eigen::VectorXd inv_diag = Eigen::VectorXd::Zero(n);
  for (Eigen::Index row = 0; row < a.outerSize(); ++row)
    for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(a, row); it; ++it)
      inv_diag[it.col()] += it.value() * it.value();
  if (r.nonZeros() > 0) inv_diag += r.diagonal();
  for (Eigen::Index j = 0; j < n; ++j) inv_diag[j] = inv_diag[j] > 0.0 ? 1.0 / inv_diag[j] : 0.0;
  return cgls_preconditioned(
      a, b, r, [&inv_diag](const Eigen::VectorXd& s) -> Eigen::VectorXd { return inv_diag.cwiseProduct(s); },
      options);
}

}  // namespace tfm
