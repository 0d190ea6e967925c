// Preconditioned CGLS on an explicit sparse matrix (Eigen), in double. With Jacobi
// preconditioning the paper's CPU CGLS baseline, run on the explicit A = S (x) I_4 of
// host/solvers/eigen_baseline.h as one system; with any preconditioner the double reference of
// the GPU `cgls` solver's iteration.
#pragma once

#include <cstdint>
#include <functional>

#include <Eigen/SparseCore>

namespace tfm {

struct CglsOptions {
  double tolerance = 1e-6;        // stop when ||A^T r - R x|| <= tolerance * ||A^T b||
  uint32_t max_iterations = 1000;
};

struct CglsResult {
  Eigen::VectorXd x;
  uint32_t iterations = 0;
  double relative_residual = 0.0;  // ||A^T r - R x|| / ||A^T b|| at the end
  bool converged = false;
};

// z = P^-1 s for a symmetric positive (semi-)definite preconditioner P.
using CglsPreconditionerFn = std::function<Eigen::VectorXd(const Eigen::VectorXd&)>;

// Minimizes ||A x - b||^2 + x^T R x (R symmetric positive semi-definite, may be empty = 0) from
// x = 0 by CGLS preconditioned with P (Bjorck's PCGLS: z = P^-1 (A^T r - R x)). Throws
// std::invalid_argument on mismatched sizes.
CglsResult cgls_preconditioned(const Eigen::SparseMatrix<double, Eigen::RowMajor>& a, const Eigen::VectorXd& b,
                               const Eigen::SparseMatrix<double>& r, const CglsPreconditionerFn& inverse,
                               const CglsOptions& options = {});

// Minimizes ||A x - b||^2 + x^T R x (R symmetric positive semi-definite, may be empty = 0) from
// x = 0 by preconditioned CGLS (Bjorck): right preconditioner diag(A^T A + R)^{-1/2}; columns
// with a zero diagonal stay 0. Throws std::invalid_argument on mismatched sizes.
CglsResult cgls_jacobi(const Eigen::SparseMatrix<double, Eigen::RowMajor>& a, const Eigen::VectorXd& b,
                       const Eigen::SparseMatrix<double>& r, const CglsOptions& options = {});

}  // namespace tfm
