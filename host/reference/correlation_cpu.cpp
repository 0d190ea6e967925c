// Double-precision references of the correlation measures, each written from its textbook
// definition (pair counting, O(M^2) neighbour searches) and sharing no code with the kernels'
// algorithms, so that tests compare two independent computations.
#include "tfmatch/reference/correlation_cpu.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>

#include "tfmatch/model/correlation_reference.h"

namespace tfm {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// NaN, or with `finite` (needs_finite_members) also ±Inf: a member without a value.
bool has_no_value(std::span<const double> v, bool finite) {
  return std::any_of(v.begin(), v.end(), [&](double a) { return std::isnan(a) || (finite && std::isinf(a)); });
}

bool is_constant(std::span<const double> v) {
  return std::all_of(v.begin(), v.end(), [&](double a) { return a == v[0]; });
}

// The series must pair up and have at least 3 members; then NaN anywhere (with `finite` ±Inf too)
// gives NaN and a constant series `constant_value` (kernels/correlation.h). Returns true when that
// settles the result.
bool special_case(std::span<const double> x, std::span<const double> y, const char* measure,
                  double constant_value, double& result, bool finite = false) {
  if (x.size() != y.size())
    throw std::invalid_argument(std::string(measure) + ": series of " + std::to_string(x.size()) + " and " +
                                std::to_string(y.size()) + " values");
  if (x.size() < 3)
    throw std::invalid_argument(std::string(measure) + ": an ensemble needs at least 3 members (got " +
                                std::to_string(x.size()) + ")");
  if (has_no_value(x, finite) || has_no_value(y, finite)) {
    result = kNaN;
    return true;
  }
  if (is_constant(x) || is_constant(y)) {
    result = constant_value;
    return true;
  }
  return false;
}

// Fractional rank of each value: 1 + (values below) + (other values equal) / 2.
std::vector<double> fractional_ranks(std::span<const double> v) {
  std::vector<double> r(v.size());
  for (size_t i = 0; i < v.size(); ++i) {
    size_t below = 0, equal = 0;
    for (double w : v) {
      below += w < v[i];
      equal += w == v[i];
    }
    r[i] = 1.0 + double(below) + double(equal - 1) / 2.0;
  }
  return r;
}

// digamma(n) = -Euler's gamma + sum_{i < n} 1/i for integers n >= 1.
double digamma(uint64_t n) {
  double s = -0.57721566490153286061;
  for (uint64_t i = 1; i < n; ++i) s += 1.0 / double(i);
  return s;
}

}  // namespace

double pearson_cpu(std::span<const double> x, std::span<const double> y) {
  double r;
  if (special_case(x, y, "pearson", kNaN, r, needs_finite_members(CorrelationMeasure::Pearson))) return r;
  const double n = double(x.size());
  double mx = 0.0, my = 0.0;
  for (size_t i = 0; i < x.size(); ++i) mx += x[i], my += y[i];
  mx /= n;
  my /= n;
  double sxy = 0.0, sxx = 0.0, syy = 0.0;
  for (size_t i = 0; i < x.size(); ++i) {
    sxy += (x[i] - mx) * (y[i] - my);
    sxx += (x[i] - mx) * (x[i] - mx);
    syy += (y[i] - my) * (y[i] - my);
  }
  return sxy / std::sqrt(sxx * syy);
}

double spearman_cpu(std::span<const double> x, std::span<const double> y) {
  double r;
  if (special_case(x, y, "spearman", kNaN, r)) return r;
  return pearson_cpu(fractional_ranks(x), fractional_ranks(y));
}

double kendall_tau_b_cpu(std::span<const double> x, std::span<const double> y) {
  double r;
  if (special_case(x, y, "kendall", kNaN, r)) return r;
  // Every pair once: concordant, discordant, tied in x only, in y only, in both.
  uint64_t concordant = 0, discordant = 0, x_only = 0, y_only = 0, both = 0;
  for (size_t i = 0; i < x.size(); ++i)
    for (size_t j = i + 1; j < x.size(); ++j) {
      const double dx = x[i] - x[j], dy = y[i] - y[j];
      if (dx == 0 && dy == 0) ++both;
      else if (dx == 0) ++x_only;
      else if (dy == 0) ++y_only;
      else if ((dx > 0) == (dy > 0)) ++concordant;
      else ++discordant;
    }
  const double n0 = double(x.size()) * double(x.size() - 1) / 2.0;
  const double n1 = double(x_only + both), n2 = double(y_only + both);
  return (double(concordant) - double(discordant)) / std::sqrt((n0 - n1) * (n0 - n2));
}

double mutual_information_binned_cpu(std::span<const double> x, std::span<const double> y, uint32_t bins) {
  double r;
  if (special_case(x, y, "mi-binned", 0.0, r, needs_finite_members(CorrelationMeasure::MiBinned))) return r;
  if (bins < 2) throw std::invalid_argument("mi-binned: bins must be at least 2");
  auto binner = [bins](std::span<const double> v) {
    const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
    std::vector<uint32_t> b(v.size());
    for (size_t i = 0; i < v.size(); ++i)
      b[i] = std::min(uint32_t(std::floor((v[i] - *lo) / (*hi - *lo) * bins)), bins - 1);
    return b;
  };
  const std::vector<uint32_t> bx = binner(x), by = binner(y);
  std::map<std::pair<uint32_t, uint32_t>, double> joint;
  std::vector<double> px(bins, 0.0), py(bins, 0.0);
  const double n = double(x.size());
  for (size_t i = 0; i < x.size(); ++i) {
    joint[{bx[i], by[i]}] += 1.0 / n;
    px[bx[i]] += 1.0 / n;
    py[by[i]] += 1.0 / n;
  }
  double mi = 0.0;
  for (const auto& [cell, p] : joint) mi += p * std::log(p / (px[cell.first] * py[cell.second]));
  return mi;
}

double mutual_information_kraskov_cpu(std::span<const double> x, std::span<const double> y, uint32_t k) {
  double r;
  if (special_case(x, y, "mi-kraskov", 0.0, r, needs_finite_members(CorrelationMeasure::MiKraskov))) return r;
  const size_t n = x.size();
  if (k < 1 || k >= n) throw std::invalid_argument("mi-kraskov: k must be 1.." + std::to_string(n - 1));
  double sum = 0.0;
  std::vector<double> d;
  for (size_t i = 0; i < n; ++i) {
    d.clear();
    for (size_t j = 0; j < n; ++j)
      if (j != i) d.push_back(std::max(std::abs(x[i] - x[j]), std::abs(y[i] - y[j])));
    std::nth_element(d.begin(), d.begin() + (k - 1), d.end());
    const double eps = d[k - 1];
    uint64_t nx = 0, ny = 0;
    for (size_t j = 0; j < n; ++j) {
      if (j == i) continue;
      nx += std::abs(x[i] - x[j]) < eps;
      ny += std::abs(y[i] - y[j]) < eps;
    }
    sum += digamma(nx + 1) + digamma(ny + 1);
  }
  return digamma(k) + digamma(n) - sum / double(n);
}

double correlation_cpu(std::span<const double> x, std::span<const double> y, const CorrelationParams& params) {
  validate_correlation_params(params, uint32_t(x.size()));
  switch (params.measure) {
    case CorrelationMeasure::Pearson: return pearson_cpu(x, y);
    case CorrelationMeasure::Spearman: return spearman_cpu(x, y);
    case CorrelationMeasure::Kendall: return kendall_tau_b_cpu(x, y);
    case CorrelationMeasure::MiBinned: return mutual_information_binned_cpu(x, y, params.bins);
    case CorrelationMeasure::MiKraskov: return mutual_information_kraskov_cpu(x, y, params.k);
    case CorrelationMeasure::MiCoefficient: {
      const double mi = mutual_information_kraskov_cpu(x, y, params.k);
      return std::isnan(mi) ? mi : std::sqrt(1.0 - std::exp(-2.0 * std::max(mi, 0.0)));
    }
  }
  throw std::invalid_argument("unknown correlation measure");
}

std::vector<double> correlation_field_reference(const EnsembleView& ens, std::span<const float> reference,
                                                const CorrelationParams& params) {
  validate_correlation_inputs(ens, reference, params);
  const std::vector<double> x(reference.begin(), reference.end());
  std::vector<double> out(ens.voxel_count), y(ens.member_count);
  for (uint64_t v = 0; v < ens.voxel_count; ++v) {
    for (uint32_t m = 0; m < ens.member_count; ++m) y[m] = ens.at(m, v);
    out[v] = correlation_cpu(x, y, params);
  }
  return out;
}

}  // namespace tfm
