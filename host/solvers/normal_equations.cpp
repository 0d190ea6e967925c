// The host solver of the tridiagonal normal equations: regularization, cond(M), the O(N) solve.
#include "tfmatch/solvers/normal_equations.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "tfmatch/model/parameter_names.h"

namespace tfm {

Regularization absolute_regularization(const NormalEquations& eq, const SolveOptions& options) {
  for (const auto& [name, value] : {std::pair{"ridge", options.ridge}, std::pair{"smooth", options.smooth}})
    if (!(value >= 0) || !std::isfinite(value))
      throw std::invalid_argument(parameter(name) + ": regularization weights must be finite and >= 0");
  // "--smooth 2e+09 is beyond 1e+09, where <why>; at 1e+09 the TF is already <limit>".
  const auto refuse_above = [](const char* name, double value, double max, const char* why, const char* limit) {
    if (value <= max) return;
    std::ostringstream os;
    os << parameter(name) << " " << value << " is beyond " << max << ", where " << why << "; at " << max
       << " the TF is already " << limit;
    throw std::invalid_argument(os.str());
  };
  refuse_above("ridge", options.ridge, kMaxRelativeRidge, "the regularized matrix leaves double's range",
               "0 to within 1e-100, which heavier ridges tend to");
  refuse_above("smooth", options.smooth, kMaxRelativeSmooth,
               "double precision no longer resolves the data under the smoothness term",
               "the constant mean reference colour that heavier smoothing tends to");
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

  SolveResult result;
  for (uint32_t j = 0; j < n; ++j) result.unreferenced_entries += eq.diag[j] == 0.0 ? 1 : 0;

  // Regularized tridiagonal matrix: M + ridge I + smooth D^T D (first differences), both scaled
  // by mean(diag M) so they keep their meaning across volume sizes.
  const Tridiagonal reg = regularized_matrix(eq, absolute_regularization(eq, options));

  const auto [lambda_min, lambda_max] = tridiagonal_extreme_eigenvalues(reg);
  result.lambda_min = lambda_min;
  result.lambda_max = lambda_max;
  // M is positive semi-definite; rounding can make a zero eigenvalue slightly negative.
  const double singular_tol = 1e-12 * std::abs(result.lambda_max);
  bool singular = result.lambda_min <= singular_tol;
  result.cond = singular ? std::numeric_limits<double>::infinity() : result.lambda_max / result.lambda_min;
  const bool regularized = options.ridge > 0 || options.smooth > 0;
  result.error_amplification = result.cond;
  if (regularized && !singular) {
    const double data_max = tridiagonal_extreme_eigenvalues(Tridiagonal{eq.diag, eq.off}).second;
    result.error_amplification = std::max(data_max, 0.0) / result.lambda_min;
  }

  const Eigen::MatrixXd rhs = eq.rhs;
  bool rank_revealing = options.factorization == Factorization::Auto;
  if (!rank_revealing) {
    result.x = solve_tridiagonal_ldlt(reg, rhs);
    result.factorization = "ldlt";
    if (!result.x.allFinite()) {
      // A singular M the plain LDL^T cannot pivot around.
      rank_revealing = true;
      result.warnings.push_back("LDL^T produced non-finite values; used the rank-revealing minimum-norm solve instead");
    }
  }
  if (rank_revealing) {
    // The rank is decided at the precision of M's float32 data, not of M + R: R is exact.
    MinNormSolve solve = solve_psd_tridiagonal_min_norm(reg, rhs, kDependentPivot, eq.diag);
    result.x = solve.x;
    result.dependent_entries = solve.dependent;
    const bool deficient = solve.unreferenced + solve.dependent > 0;
    result.factorization = deficient ? "min-norm-ldlt" : "ldlt";
    if (deficient && !singular) {
      // Rank decided at the data's float32 precision (kDependentPivot), coarser than the
      // eigenvalue test: the computed M is nearly, not exactly, singular.
      singular = true;
      result.cond = std::numeric_limits<double>::infinity();
      result.error_amplification = result.cond;
    }
  }

  if (singular && options.ridge == 0 && options.smooth == 0) {
    std::ostringstream os;
    os << "M is singular: " << result.unreferenced_entries << " TF entries are touched by no voxel and were set to 0";
    if (result.dependent_entries > 0)
      os << ", and " << result.dependent_entries << " runs of entries are fixed by the data only up to one "
         << "combination each (their minimum-norm values were taken)";
    os << "; " << parameter("smooth") << " fills them from their neighbours";
    result.warnings.push_back(os.str());
  } else if (result.error_amplification > options.cond_warning) {
    const std::string cgls = parameter("solver") + " cgls" +
                             (options.streamed ? " (" + parameter("stream") + " off, in one process)" : "");
    std::ostringstream os;
    if (regularized)
      os << "lambda_max(M) / lambda_min(M + regularization) = " << result.error_amplification << " exceeds "
         << options.cond_warning << ": M carries ~1e-7 relative error from float32 data, so x may be wrong by that "
         << "ratio * 1e-7; consider " << cgls << " or a larger " << parameter("ridge") << " or "
         << parameter("smooth");
    else
      os << "cond(M) = " << result.cond << " exceeds " << options.cond_warning
         << ": M carries ~1e-7 relative error from float32 data, so x may be wrong by cond*1e-7; consider "
         << cgls << " or " << parameter("smooth");
    result.warnings.push_back(os.str());
  }

  result.tf.rgba.resize(n);
  double moved = 0.0;  // the farthest a clamp moved a component
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) {
      double v = result.x(j, c);
      double clamped = std::clamp(v, 0.0, 1.0);
      if (clamped != v) ++result.clamped_values;
      moved = std::max(moved, std::abs(clamped - v));
      result.tf.rgba[j][c] = clamped;
    }
  // Counted always (details), said only when a clamp matters: a field fitted to itself lands a
  // TF's zeros on rounding (-1e-9) and the box-constrained optimum would be the same TF.
  if (moved > kClampWarnDistance) {
    std::ostringstream os;
    os << result.clamped_values << (result.clamped_values == 1 ? " TF component fell" : " TF components fell")
       << " outside [0,1] and " << (result.clamped_values == 1 ? "was" : "were") << " clamped (by up to "
       << std::setprecision(3) << moved << "); " << parameter("solver") << " qp gives the exact box-constrained optimum";
    result.warnings.push_back(os.str());
  }
  return result;
}

}  // namespace tfm
