// O(N) solves and extreme eigenvalues of symmetric (semi-)definite tridiagonal matrices.
#include "tfmatch/solvers/tridiagonal.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <stdexcept>
#include <string>

#include "tfmatch/model/cancellation.h"

namespace tfm {
namespace {

// How entry j took part in the LDL^T sweep.
enum class Entry : uint8_t {
  Unreferenced,  // T_jj <= 0: x_j = 0, no coupling on either side
  Start,         // first entry of a run: pivot T_jj
  Coupled,       // eliminated with entry j-1 (factor l_j)
  Dependent,     // coupled, but its pivot fell below the tolerance: x_j = 0 in the basic solution
};

void check_sizes(const Tridiagonal& t, Eigen::Index rows) {
  const size_t n = t.diag.size();
  if (n == 0 || t.off.size() + 1 != n || (rows >= 0 && size_t(rows) != n))
    throw std::invalid_argument("tridiagonal solve: sizes of the diagonal, off-diagonal and right-hand side do not match");
}

// A pivot this many units of double roundoff of its diagonal is zero whatever the data's noise:
// the elimination's cancellation alone can leave that much.
constexpr double kRoundoffPivot = 64 * DBL_EPSILON;

// Forward sweep: LDL^T (pivot, l) and L y = b in place of b, with entry kinds. With `tolerance`
// < 0 no entry is unreferenced or dependent (plain LDL^T). Entry j is dependent when its pivot is
// at most tolerance * data_diag[j] (t.diag[j] when data_diag is empty) or kRoundoffPivot * t.diag[j].
void factor_and_forward(const Tridiagonal& t, double tolerance, std::span<const double> data_diag, Eigen::MatrixXd& y,
                        std::vector<double>& pivot, std::vector<double>& l, std::vector<Entry>& kind) {
  const size_t n = t.diag.size();
  const bool decide = tolerance >= 0;
  bool open = false;  // the previous entry ends an open run this one couples to
  for (size_t j = 0; j < n; ++j) {
    // Long systems (N = 65536 is allowed) stay interruptible; checking every 4096 entries costs
    // nothing.
    if ((j & 4095) == 4095) checkpoint("solve");
    const double d = t.diag[j];
    if (decide && !(d > 0.0)) {
      kind[j] = Entry::Unreferenced;
      y.row(Eigen::Index(j)).setZero();
      open = false;
      continue;
    }
    double p = d;
    if (open) {
      l[j] = t.off[j - 1] / pivot[j - 1];
      p -= l[j] * t.off[j - 1];
      y.row(Eigen::Index(j)) -= l[j] * y.row(Eigen::Index(j - 1));
      kind[j] = Entry::Coupled;
    } else {
      l[j] = 0.0;
      kind[j] = Entry::Start;
    }
    pivot[j] = p;
    if (decide && p <= std::max(tolerance * (data_diag.empty() ? d : data_diag[j]), kRoundoffPivot * d)) {
      kind[j] = Entry::Dependent;
      y.row(Eigen::Index(j)).setZero();
      open = false;  // column j is left out: the next entry starts a run of its own
      continue;
    }
    open = true;
  }
}

// Back substitution L^T x = D^-1 y in place.
void backward(const std::vector<double>& pivot, const std::vector<double>& l, const std::vector<Entry>& kind,
              Eigen::MatrixXd& x) {
  const size_t n = pivot.size();
  for (size_t j = n; j-- > 0;) {
    if (kind[j] == Entry::Unreferenced || kind[j] == Entry::Dependent) continue;  // 0
    x.row(Eigen::Index(j)) /= pivot[j];
    if (j + 1 < n && kind[j + 1] == Entry::Coupled) x.row(Eigen::Index(j)) -= l[j + 1] * x.row(Eigen::Index(j + 1));
  }
}

// The null vector of the run [s..j] (j dependent) from the sweep's factors: z_j = 1,
// z_i = -l_{i+1} z_{i+1}. It can grow or decay geometrically along a long run: it is rescaled by
// 2^-kScaleBits whenever it passes 2^kScaleBits and the scales are applied on a second pass, so it
// neither overflows nor costs more than O(run length). Its largest entry is about 1 to 2^kScaleBits.
void null_vector(size_t s, size_t j, const std::vector<double>& l, std::vector<double>& z, std::vector<size_t>& rescaled_at) {
  constexpr int kScaleBits = 200;
  const double big = std::ldexp(1.0, kScaleBits);
  rescaled_at.clear();
  z[j] = 1.0;
  for (size_t i = j; i-- > s;) {
    z[i] = -l[i + 1] * z[i + 1];
    if (std::abs(z[i]) > big) {
      z[i] = std::ldexp(z[i], -kScaleBits);
      rescaled_at.push_back(i);  // entries after i are 2^kScaleBits too large relative to z[i]
    }
  }
  size_t events = rescaled_at.size();  // rescales at positions < m, for m walking up from s
  for (size_t m = s; m <= j; ++m) {
    while (events > 0 && rescaled_at[events - 1] < m) --events;
    const size_t below = rescaled_at.size() - events;
    // (past 6 rescales a value is below 2^-1000 of the largest: 0 either way)
    if (below > 0) z[m] = std::ldexp(z[m], -kScaleBits * int(std::min<size_t>(below, 8)));
  }
}

// Plain LDL^T solve of the positive definite block [first, last] of t with the rows of b, into
// the same rows of x; nothing for an empty block.
void solve_block(const Tridiagonal& t, const Eigen::MatrixXd& b, size_t first, size_t last, Eigen::MatrixXd& x,
                 std::vector<double>& pivot, std::vector<double>& l) {
  if (first > last) return;
  for (size_t k = first; k <= last; ++k) {
    x.row(Eigen::Index(k)) = b.row(Eigen::Index(k));
    pivot[k] = t.diag[k];
    if (k > first) {
      l[k] = t.off[k - 1] / pivot[k - 1];
      pivot[k] -= l[k] * t.off[k - 1];
      x.row(Eigen::Index(k)) -= l[k] * x.row(Eigen::Index(k - 1));
    }
  }
  for (size_t k = last + 1; k-- > first;) {
    x.row(Eigen::Index(k)) /= pivot[k];
    if (k < last) x.row(Eigen::Index(k)) -= l[k + 1] * x.row(Eigen::Index(k + 1));
  }
}

// Replaces x on the run [s..j] by its minimum-norm solution. The basic solution is taken with the
// entry where the null vector z is largest left out (x_k = 0; the run splits into two positive
// definite blocks, which then have bounded solutions: leaving out the last entry instead makes
// them grow like z itself, 3^length for cells of weight 3/4), then z's component is removed.
void min_norm_run(const Tridiagonal& t, const Eigen::MatrixXd& b, size_t s, size_t j, const std::vector<double>& l,
                  Eigen::MatrixXd& x, std::vector<double>& z, std::vector<size_t>& rescaled_at, std::vector<double>& pivot2,
                  std::vector<double>& l2) {
  null_vector(s, j, l, z, rescaled_at);
  size_t k = j;
  for (size_t m = s; m <= j; ++m)
    if (std::abs(z[m]) > std::abs(z[k])) k = m;
  if (k > s) solve_block(t, b, s, k - 1, x, pivot2, l2);
  solve_block(t, b, k + 1, j, x, pivot2, l2);
  x.row(Eigen::Index(k)).setZero();
  double zz = 0.0;
  Eigen::RowVectorXd zx = Eigen::RowVectorXd::Zero(x.cols());
  for (size_t m = s; m <= j; ++m) {
    zz += z[m] * z[m];
    zx += z[m] * x.row(Eigen::Index(m));
  }
  const Eigen::RowVectorXd c = zx / zz;
  for (size_t m = s; m <= j; ++m) x.row(Eigen::Index(m)) -= z[m] * c;
}

// Number of eigenvalues of t below `x` (Sturm sequence of T - x I). `pivmin` replaces a zero
// pivot, as LAPACK's bisection does.
size_t count_below(const Tridiagonal& t, double x, double pivmin) {
  size_t count = 0;
  double q = 1.0;
  for (size_t i = 0; i < t.diag.size(); ++i) {
    q = t.diag[i] - x - (i > 0 ? t.off[i - 1] * t.off[i - 1] / q : 0.0);
    if (std::abs(q) < pivmin) q = -pivmin;
    if (q < 0.0) ++count;
  }
  return count;
}

}  // namespace

MinNormSolve solve_psd_tridiagonal_min_norm(const Tridiagonal& t, const Eigen::MatrixXd& b, double tolerance,
                                            std::span<const double> data_diag) {
  check_sizes(t, b.rows());
  const size_t n = t.diag.size();
  if (!data_diag.empty() && data_diag.size() != n)
    throw std::invalid_argument("tridiagonal solve: the data diagonal's size does not match the matrix");
  MinNormSolve out;
  out.x = b;
  std::vector<double> pivot(n), l(n);
  std::vector<Entry> kind(n);
  factor_and_forward(t, std::max(tolerance, 0.0), data_diag, out.x, pivot, l, kind);
  backward(pivot, l, kind, out.x);
  std::vector<double> z(n), pivot2(n), l2(n);
  std::vector<size_t> rescaled_at;
  for (size_t j = 0; j < n; ++j) {
    if (kind[j] == Entry::Unreferenced) ++out.unreferenced;
    if (kind[j] != Entry::Dependent) continue;
    ++out.dependent;
    size_t s = j - 1;  // a dependent entry is coupled, so its run starts before it
    while (kind[s] == Entry::Coupled) --s;
    min_norm_run(t, b, s, j, l, out.x, z, rescaled_at, pivot2, l2);
  }
  return out;
}

Eigen::MatrixXd solve_tridiagonal_ldlt(const Tridiagonal& t, const Eigen::MatrixXd& b) {
  check_sizes(t, b.rows());
  const size_t n = t.diag.size();
  Eigen::MatrixXd x = b;
  std::vector<double> pivot(n), l(n);
  std::vector<Entry> kind(n);
  factor_and_forward(t, -1.0, {}, x, pivot, l, kind);
  backward(pivot, l, kind, x);
  return x;
}

TridiagonalLdlt factor_positive_definite(const Tridiagonal& t) {
  check_sizes(t, -1);
  const size_t n = t.diag.size();
  TridiagonalLdlt f{std::vector<double>(n), std::vector<double>(n - 1)};
  for (size_t j = 0; j < n; ++j) {
    double p = t.diag[j];
    if (j > 0) {
      f.lower[j - 1] = t.off[j - 1] / f.pivot[j - 1];
      p -= f.lower[j - 1] * t.off[j - 1];
    }
    if (!(p > 0.0) || !std::isfinite(p))
      throw std::invalid_argument("LDL^T: the tridiagonal matrix is not positive definite (pivot " +
                                  std::to_string(j) + " is " + std::to_string(p) + ")");
    f.pivot[j] = p;
  }
  return f;
}

std::pair<double, double> tridiagonal_extreme_eigenvalues(const Tridiagonal& t) {
  check_sizes(t, -1);
  const size_t n = t.diag.size();
  // Gershgorin interval, and the largest squared off-diagonal for the zero-pivot guard.
  double lo = HUGE_VAL, hi = -HUGE_VAL, max_off2 = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const double r = (i > 0 ? std::abs(t.off[i - 1]) : 0.0) + (i + 1 < n ? std::abs(t.off[i]) : 0.0);
    lo = std::min(lo, t.diag[i] - r);
    hi = std::max(hi, t.diag[i] + r);
    if (i + 1 < n) max_off2 = std::max(max_off2, t.off[i] * t.off[i]);
  }
  if (!std::isfinite(lo) || !std::isfinite(hi)) throw std::invalid_argument("tridiagonal eigenvalues: non-finite entries");
  const double norm = std::max(std::abs(lo), std::abs(hi));
  const double pivmin = DBL_MIN * std::max(1.0, max_off2);
  // Below this width an interval says nothing more: roundoff of the Sturm count is ~eps * norm.
  const double atol = std::max(1e-4 * DBL_EPSILON * norm, 4 * pivmin);
  const double pad = 2 * DBL_EPSILON * norm + atol;
  auto bisect = [&](size_t k) {  // the k-th smallest eigenvalue (1-based)
    double a = lo - pad, b = hi + pad;
    for (int step = 0; step < 256; ++step) {
      if (b - a <= std::max(2 * DBL_EPSILON * std::max(std::abs(a), std::abs(b)), atol)) break;
      const double mid = 0.5 * (a + b);
      (count_below(t, mid, pivmin) >= k ? b : a) = mid;
    }
    return 0.5 * (a + b);
  };
  return {bisect(1), bisect(n)};
}

}  // namespace tfm
