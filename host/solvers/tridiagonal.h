// Symmetric positive semi-definite tridiagonal systems in O(N) time and memory, for any N and
// any rank: the minimum-norm solution of the normal equations M x = S^T b (rank decided entry by
// entry during an LDL^T sweep), plain LDL^T, and the extreme eigenvalues by Sturm bisection.
#pragma once

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace tfm {

// A symmetric tridiagonal matrix: diag (n) and off-diagonal (n-1).
struct Tridiagonal {
  std::vector<double> diag;
  std::vector<double> off;
};

struct MinNormSolve {
  Eigen::MatrixXd x;          // n x k
  uint32_t unreferenced = 0;  // zero diagonal entries (TF entries no voxel touches): x = 0 there
  uint32_t dependent = 0;     // entries whose LDL^T pivot fell below the tolerance (see below)
};

// Relative pivot below which an entry counts as dependent: M = S^T S is assembled from float32
// products (relative error ~6e-8 each), so an exactly dependent column leaves a pivot of ~1e-7 of
// its diagonal, not 0. Treating every pivot under 1e-6 d_j as zero changes the least-squares
// objective by at most 1e-6 d_j x_j^2, far below what float32 data can resolve.
constexpr double kDependentPivot = 1e-6;

// The minimum-norm least-squares solution of T X = B for a symmetric positive semi-definite
// tridiagonal T (B: n x k). Entries with T_jj <= 0 are unreferenced (x_j = 0). An LDL^T sweep
// runs over the rest; when entry j's pivot is <= tolerance * T_jj, its column of S lies (nearly)
// in the span of the columns since the run began, the run [s..j] is closed and the sweep restarts
// at j + 1. Each closed run has one null vector z (z_j = 1, M_[s..j-1] z_[s..j-1] = -T_{j-1,j}
// e_last); the run is solved with the entry where |z| is largest left out (two positive definite
// blocks) and made orthogonal to z, which in exact arithmetic gives the minimum-norm solution.
// Runs are disjoint, so the whole solve is O(n k).
//
// `data_diag` (n entries, or empty for T's own diagonal) is the part of T's diagonal that carries
// the data's float32 error, against which the tolerance is measured: for T = M + R with an exactly
// known regularization R, M's diagonal. R's entries are exact, so a pivot that R lifts above the
// data's noise is no rank decision to make: a heavily smoothed M + s D^T D (s >> M) has a last
// pivot of M's size, far below tolerance * T_jj but well determined. A pivot within a few units of
// double roundoff of T_jj is zero whatever the tolerance. Throws std::invalid_argument on
// mismatched sizes.
MinNormSolve solve_psd_tridiagonal_min_norm(const Tridiagonal& t, const Eigen::MatrixXd& b,
                                            double tolerance = kDependentPivot, std::span<const double> data_diag = {});

// LDL^T without any rank decision (a zero pivot gives inf/NaN in x): O(n k).
Eigen::MatrixXd solve_tridiagonal_ldlt(const Tridiagonal& t, const Eigen::MatrixXd& b);

// L D L^T of a symmetric positive definite tridiagonal T: pivots D_j (n) and multipliers
// lower[j] = L_{j+1,j} (n-1), so that T = L diag(pivot) L^T with L unit lower bidiagonal. For
// preconditioners (the cgls solver's): O(n), no rank decision. Throws std::invalid_argument when
// the sizes disagree or a pivot is not positive (T is not positive definite).
struct TridiagonalLdlt {
  std::vector<double> pivot;
  std::vector<double> lower;
};
TridiagonalLdlt factor_positive_definite(const Tridiagonal& t);

// The smallest and largest eigenvalue of a symmetric tridiagonal matrix, by bisection on Sturm
// counts from the Gershgorin interval: O(n) per step, about 100 steps, absolute error within a few
// units of roundoff times the matrix norm (as a QR iteration's) and relative error ~1e-15 for
// eigenvalues well above that. Throws std::invalid_argument for an empty or inconsistent matrix.
std::pair<double, double> tridiagonal_extreme_eigenvalues(const Tridiagonal& t);

}  // namespace tfm
