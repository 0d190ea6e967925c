// Exact box-constrained least squares on the tridiagonal normal equations: min ||S x - b||^2 +
// x^T R x subject to 0 <= x <= 1, per channel, by a primal active-set method whose subproblems are
// O(N) tridiagonal solves; and the KKT residual that certifies a solution.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tfmatch/model/transfer_function.h"
#include "tfmatch/solvers/normal_equations.h"

namespace tfm {

struct BoxQpOptions {
  double lower = 0.0;
  double upper = 1.0;
  uint32_t max_iterations = 0;  // per channel; 0: 10 N + 100
  // A bound leaves the working set when its multiplier, in TF units (g_j / H_jj), is below
  // -tolerance. Rounding puts ~1e-16 * (a few) there, so 1e-12 never drops a bound for noise.
  double tolerance = 1e-12;
};

struct BoxQpStats {
  uint32_t iterations = 0;  // subproblem solves (each adds or drops at most one bound)
  uint32_t at_lower = 0;    // components on a bound at the solution
  uint32_t at_upper = 0;
  bool converged = false;   // false: the iteration cap was hit
  double kkt = 0.0;         // box_kkt_residual() of the result
};

// Minimizes x^T H x - 2 c^T x over lower <= x <= upper for a symmetric positive semi-definite
// tridiagonal H. `x` holds the start (projected to the box) and receives the solution. A
// component with H_jj <= 0 (an unreferenced TF entry: its row of H is zero) does not enter the
// quadratic; it goes to the bound c_j favours, or to clamp(0) when c_j = 0, as the normal
// equations set unreferenced entries to 0. When H is singular on the free components the result
// is one of the minimizers (all have the same objective). Throws std::invalid_argument on
// mismatched sizes or lower > upper.
BoxQpStats solve_box_qp(const Tridiagonal& h, const Eigen::VectorXd& c, Eigen::VectorXd& x,
                        const BoxQpOptions& options = {});

// Optimality residual in TF units: the largest bound violation, and the largest
// |x_j - clamp(x_j + p_j, lower, upper)| over the free components F, with p_F the Newton step
// H_FF p_F = -g_F, g = H x - c; a component is free unless H_jj = 0 or it sits on a bound with a
// multiplier of the right sign (g_j >= 0 at the lower, <= 0 at the upper). Zero exactly at a KKT
// point of the problem above; where the bounds held are the optimum's, the distance to it on F,
// however ill-conditioned H is (a diagonal step reads small along smooth directions under heavy
// smoothing).
double box_kkt_residual(const Tridiagonal& h, const Eigen::VectorXd& c, const Eigen::VectorXd& x,
                        double lower = 0.0, double upper = 1.0);

// Unconstrained minimizer of x^T H x - 2 c^T x by tridiagonal LDL^T, with pivots floored at
// 1e-14 H_jj so that a singular H gives large but finite values instead of inf/NaN; components
// with H_jj <= 0 are 0.
Eigen::VectorXd solve_tridiagonal_floored(const Tridiagonal& h, const Eigen::VectorXd& c);

struct BoxQpResult {
  TransferFunction tf;                          // = x
  Eigen::Matrix<double, Eigen::Dynamic, 4> x;   // the constrained minimizer, in [0,1]
  std::array<BoxQpStats, 4> channels;
  Regularization regularization;                // absolute weights used
  std::vector<std::string> warnings;
};

// The four channels of the (regularized, see SolveOptions) normal equations, each started from
// its clamped unconstrained solution. Throws std::runtime_error if no voxel has data.
BoxQpResult solve_box_constrained(const NormalEquations& eq, const SolveOptions& options = {},
                                  const BoxQpOptions& qp = {});

}  // namespace tfm
