// Primal active-set method for the box-constrained tridiagonal least-squares problem.
#include "tfmatch/solvers/box_qp.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "tfmatch/model/cancellation.h"

namespace tfm {
namespace {

enum class Bound : uint8_t { Free, Lower, Upper, Excluded };

// Pivots below this fraction of their diagonal entry are rounding noise of a singular block.
constexpr double kPivotFloor = 1e-14;
// A free step this small (TF units) means the subproblem minimum is reached.
constexpr double kStepTolerance = 1e-13;

// Solves H_FF p_F = rhs_F on every maximal run of free components (runs decouple once the fixed
// components are taken out); p is 0 elsewhere. LDL^T with floored pivots (see kPivotFloor): a
// singular run yields a finite step, which the box then limits.
void solve_free_runs(const Tridiagonal& h, const std::vector<Bound>& state, const Eigen::VectorXd& rhs,
                     Eigen::VectorXd& p, std::vector<double>& pivot, std::vector<double>& factor,
                     double pivot_floor = kPivotFloor) {
  const size_t n = h.diag.size();
  size_t j = 0;
  while (j < n) {
    if (state[j] != Bound::Free) {
      p[j] = 0.0;
      ++j;
      continue;
    }
    size_t end = j;
    while (end < n && state[end] == Bound::Free) ++end;
    // Forward: H = L D L^T with unit bidiagonal L (factor[k] = L[k][k-1]); solve L y = rhs.
    for (size_t k = j; k < end; ++k) {
      double d = h.diag[k], y = rhs[k];
      if (k > j) {
        factor[k] = h.off[k - 1] / pivot[k - 1];
        d -= factor[k] * h.off[k - 1];
        y -= factor[k] * p[k - 1];
      }
      pivot[k] = std::max(d, pivot_floor * h.diag[k]);
      p[k] = y;  // holds y until the back substitution
    }
    // Backward: L^T p = D^-1 y.
    for (size_t k = end; k-- > j;) {
      p[k] /= pivot[k];
      if (k + 1 < end) p[k] -= factor[k + 1] * p[k + 1];
    }
    j = end;
  }
}

// g = H x - c.
void gradient(const Tridiagonal& h, const Eigen::VectorXd& c, const Eigen::VectorXd& x, Eigen::VectorXd& g) {
  const size_t n = h.diag.size();
  for (size_t j = 0; j < n; ++j) {
    double v = h.diag[j] * x[j] - c[j];
    if (j > 0) v += h.off[j - 1] * x[j - 1];
    if (j + 1 < n) v += h.off[j] * x[j + 1];
    g[j] = v;
  }
}

void check_sizes(const Tridiagonal& h, const Eigen::VectorXd& c, const Eigen::VectorXd& x) {
  const size_t n = h.diag.size();
  if (n == 0 || h.off.size() + 1 != n || size_t(c.size()) != n || size_t(x.size()) != n)
    throw std::invalid_argument("box QP: sizes of H, c and x do not match");
}

}  // namespace

Eigen::VectorXd solve_tridiagonal_floored(const Tridiagonal& h, const Eigen::VectorXd& c) {
  const size_t n = h.diag.size();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(Eigen::Index(n));
  check_sizes(h, c, x);
  std::vector<Bound> state(n);
  for (size_t j = 0; j < n; ++j) state[j] = h.diag[j] > 0.0 ? Bound::Free : Bound::Excluded;
  std::vector<double> pivot(n), factor(n);
  solve_free_runs(h, state, c, x, pivot, factor);
  return x;
}

double box_kkt_residual(const Tridiagonal& h, const Eigen::VectorXd& c, const Eigen::VectorXd& x, double lower,
                        double upper) {
  check_sizes(h, c, x);
  const size_t n = h.diag.size();
  Eigen::VectorXd g(x.size());
  gradient(h, c, x, g);
  double worst = 0.0;
  // Components on a bound whose multiplier has the right sign stay there; the others are free.
  std::vector<Bound> state(n);
  for (size_t j = 0; j < n; ++j) {
    if (!std::isfinite(x[j]) || !std::isfinite(g[j])) return std::numeric_limits<double>::infinity();
    worst = std::max({worst, lower - x[j], x[j] - upper});
    state[j] = !(h.diag[j] > 0.0)                ? Bound::Excluded
               : x[j] <= lower && g[j] >= 0.0    ? Bound::Lower
               : x[j] >= upper && g[j] <= 0.0    ? Bound::Upper
                                                 : Bound::Free;
  }
  // The Newton step on the free components, H_FF p = -g_F, taken into the box. A diagonal step
  // (g_j / H_jj) reads far too small where H is ill-conditioned: under heavy --smooth, error along
  // a smooth direction leaves a gradient of about lambda_min times it, while H_jj is near
  // lambda_max (gradient descent 0.63 from the optimum read 6e-6). Pivots are floored at
  // kResidualPivotFloor of their diagonal: rounding noise of g at a singular run's minimizer must
  // not read as a step (kPivotFloor would amplify it 1e14 times).
  constexpr double kResidualPivotFloor = 1e-10;
  Eigen::VectorXd rhs = -g, p(x.size());
  std::vector<double> pivot(n), factor(n);
  solve_free_runs(h, state, rhs, p, pivot, factor, kResidualPivotFloor);
  for (size_t j = 0; j < n; ++j)
    if (state[j] == Bound::Free) worst = std::max(worst, std::abs(x[j] - std::clamp(x[j] + p[j], lower, upper)));
  return worst;
}

BoxQpStats solve_box_qp(const Tridiagonal& h, const Eigen::VectorXd& c, Eigen::VectorXd& x,
                        const BoxQpOptions& options) {
  check_sizes(h, c, x);
  if (!(options.lower <= options.upper)) throw std::invalid_argument("box QP: lower bound above upper bound");
  const size_t n = h.diag.size();
  const double lo = options.lower, hi = options.upper;
  const uint32_t cap = options.max_iterations ? options.max_iterations : uint32_t(10 * n + 100);

  // Working set from the projected start: components on a bound keep it until their multiplier
  // says otherwise.
  std::vector<Bound> state(n);
  for (size_t j = 0; j < n; ++j) {
    if (!(h.diag[j] > 0.0)) {
      state[j] = Bound::Excluded;
      x[j] = c[j] > 0.0 ? hi : (c[j] < 0.0 ? lo : std::clamp(0.0, lo, hi));
      continue;
    }
    x[j] = std::isfinite(x[j]) ? std::clamp(x[j], lo, hi) : std::clamp(0.0, lo, hi);
    state[j] = x[j] == lo ? Bound::Lower : (x[j] == hi ? Bound::Upper : Bound::Free);
  }

  BoxQpStats stats;
  const Eigen::Index size = Eigen::Index(n);
  Eigen::VectorXd g(size), rhs(size), p(size);
  std::vector<double> pivot(n), factor(n);
  // Full (unblocked) steps since the working set last changed: the first lands on the subproblem
  // minimum, a second refines it; after that the minimum is taken as reached.
  int full_steps = 0;
  while (stats.iterations < cap) {
    // Up to 10 N steps of O(N) each: a large N must stay interruptible.
    if ((stats.iterations & 63) == 0) checkpoint("solve");
    ++stats.iterations;
    gradient(h, c, x, g);
    rhs = -g;
    solve_free_runs(h, state, rhs, p, pivot, factor);
    double step = 0.0;
    for (size_t j = 0; j < n; ++j)
      if (state[j] == Bound::Free) step = std::max(step, std::abs(p[j]));

    if (step <= kStepTolerance || full_steps >= 2) {
      // At the minimum over the working set: drop the bound whose multiplier is most negative.
      double most_negative = -options.tolerance;
      size_t drop = n;
      for (size_t j = 0; j < n; ++j) {
        double lambda = 0.0;
        if (state[j] == Bound::Lower) lambda = g[j] / h.diag[j];
        else if (state[j] == Bound::Upper) lambda = -g[j] / h.diag[j];
        else continue;
        if (lambda < most_negative) most_negative = lambda, drop = j;
      }
      if (drop == n) {
        stats.converged = true;
        break;
      }
      state[drop] = Bound::Free;
      full_steps = 0;
      continue;
    }

    // Longest step along p that stays in the box; the first bound reached joins the working set.
    double alpha = 1.0;
    size_t block = n;
    for (size_t j = 0; j < n; ++j) {
      if (state[j] != Bound::Free || p[j] == 0.0) continue;
      const double t = p[j] < 0.0 ? (lo - x[j]) / p[j] : (hi - x[j]) / p[j];
      if (t < alpha) alpha = std::max(t, 0.0), block = j;
    }
    for (size_t j = 0; j < n; ++j)
      if (state[j] == Bound::Free) x[j] = std::clamp(x[j] + alpha * p[j], lo, hi);
    if (block < n) {
      x[block] = p[block] < 0.0 ? lo : hi;
      state[block] = p[block] < 0.0 ? Bound::Lower : Bound::Upper;
      full_steps = 0;
    } else {
      ++full_steps;
    }
  }
  for (size_t j = 0; j < n; ++j) {
    stats.at_lower += x[j] == lo ? 1 : 0;
    stats.at_upper += x[j] == hi ? 1 : 0;
  }
  stats.kkt = box_kkt_residual(h, c, x, lo, hi);
  return stats;
}

BoxQpResult solve_box_constrained(const NormalEquations& eq, const SolveOptions& options, const BoxQpOptions& qp) {
  if (eq.n < 2) throw std::invalid_argument("transfer functions need at least 2 entries");
  if (eq.voxels == 0) throw std::runtime_error("no voxel has data in both fields (all NaN?): nothing to fit");
  BoxQpResult result;
  result.regularization = absolute_regularization(eq, options);
  const Tridiagonal h = regularized_matrix(eq, result.regularization);
  result.x.resize(eq.n, 4);
  for (int ch = 0; ch < 4; ++ch) {
    const Eigen::VectorXd c = eq.rhs.col(ch);
    // The clamped unconstrained solution is usually close: its bounds are mostly the right ones.
    Eigen::VectorXd x = solve_tridiagonal_floored(h, c);
    result.channels[size_t(ch)] = solve_box_qp(h, c, x, qp);
    result.x.col(ch) = x;
    if (!result.channels[size_t(ch)].converged) {
      std::ostringstream os;
      os << "box QP, channel " << "RGBA"[ch] << ": stopped after " << result.channels[size_t(ch)].iterations
         << " iterations with KKT residual " << result.channels[size_t(ch)].kkt;
      result.warnings.push_back(os.str());
    }
  }
  result.tf.rgba.resize(eq.n);
  for (uint32_t j = 0; j < eq.n; ++j)
    for (int ch = 0; ch < 4; ++ch) result.tf.rgba[j][size_t(ch)] = result.x(j, ch);
  return result;
}

}  // namespace tfm
