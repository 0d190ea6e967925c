// Host-side preparation of a correlation field's reference series.
#include "tfmatch/model/correlation_reference.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

namespace tfm {

uint32_t correlation_bin(float value, float lo, float range, uint32_t bins) {
  const float scaled = (value - lo) * float(bins);
  uint32_t b = std::min(uint32_t(scaled / range), bins - 1);
  if (b > 0 && float(b) * range > scaled) --b;
  else if (b + 1 < bins && float(b + 1) * range <= scaled) ++b;
  return b;
}

std::vector<uint32_t> ascending_order(std::span<const float> values) {
  std::vector<uint32_t> order(values.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return values[a] < values[b]; });
  return order;
}

namespace {

// For each position of `order`, the first position holding an equal value.
std::vector<uint32_t> tie_group_starts(std::span<const float> values, const std::vector<uint32_t>& order) {
  std::vector<uint32_t> first(order.size());
  for (size_t p = 0; p < order.size(); ++p)
    first[p] = p > 0 && values[order[p]] == values[order[p - 1]] ? first[p - 1] : uint32_t(p);
  return first;
}

void prepare_pearson(std::span<const float> x, CorrelationReference& r) {
  double mean = 0.0;
  for (float v : x) mean += v;
  mean /= double(x.size());
  r.values.resize(x.size());
  for (size_t m = 0; m < x.size(); ++m) {
    r.values[m] = float(double(x[m]) - mean);
    r.norm += (double(x[m]) - mean) * (double(x[m]) - mean);
  }
}

void prepare_spearman(std::span<const float> x, CorrelationReference& r) {
  const std::vector<uint32_t> order = ascending_order(x);
  const std::vector<uint32_t> first = tie_group_starts(x, order);
  const int64_t m_count = int64_t(x.size());
  r.values.resize(x.size());
  for (size_t p = 0; p < order.size();) {
    size_t end = p + 1;
    while (end < order.size() && first[end] == first[p]) ++end;
    // Positions p .. end-1 share the mean 1-based rank (p + end + 1) / 2: doubled, p + end + 1.
    const int64_t centred = int64_t(p + end + 1) - (m_count + 1);
    for (size_t q = p; q < end; ++q) r.values[order[q]] = float(centred);
    r.norm += double(centred * centred) * double(end - p);
    p = end;
  }
}

void prepare_kendall(std::span<const float> x, CorrelationReference& r) {
  r.order = ascending_order(x);
  r.group = tie_group_starts(x, r.order);
  for (size_t p = 0; p < r.group.size(); ++p) r.tied_pairs += p - r.group[p];
}

}  // namespace

void validate_correlation_inputs(const EnsembleView& ens, std::span<const float> reference,
                                 const CorrelationParams& params) {
  const std::string name = correlation_measure_name(params.measure);
  validate_correlation_params(params, ens.member_count);
  if (ens.values == nullptr || ens.voxel_count == 0) throw std::invalid_argument(name + ": the ensemble has no voxels");
  if (reference.size() != ens.member_count)
    throw std::invalid_argument(name + ": the reference series has " + std::to_string(reference.size()) +
                                " values for " + std::to_string(ens.member_count) + " members");
}

void gather_series(const EnsembleView& ens, uint64_t first, uint32_t count, float* dst) {
  // In tiles of 16 voxels, so the 16 series being written stay in cache across the members.
  constexpr uint32_t kTile = 16;
  const uint32_t members = ens.member_count;
  for (uint32_t i0 = 0; i0 < count; i0 += kTile) {
    const uint32_t i1 = std::min(count, i0 + kTile);
    for (uint32_t m = 0; m < members; ++m) {
      const float* src = ens.values + m * ens.voxel_count + first;
      for (uint32_t i = i0; i < i1; ++i) dst[uint64_t(i) * members + m] = src[i];
    }
  }
}

CorrelationReference prepare_correlation_reference(std::span<const float> reference, const CorrelationParams& params) {
  validate_correlation_params(params, uint32_t(reference.size()));
  CorrelationReference r;
  r.params = params;
  r.members = uint32_t(reference.size());
  const bool finite = needs_finite_members(params.measure);
  r.has_nan = std::any_of(reference.begin(), reference.end(),
                          [&](float v) { return std::isnan(v) || (finite && std::isinf(v)); });
  if (r.has_nan) return r;
  const auto [lo, hi] = std::minmax_element(reference.begin(), reference.end());
  r.lo = *lo;
  r.hi = *hi;
  r.constant = r.lo == r.hi;
  const uint32_t m_count = r.members;
  switch (params.measure) {
    case CorrelationMeasure::Pearson: prepare_pearson(reference, r); break;
    case CorrelationMeasure::Spearman: prepare_spearman(reference, r); break;
    case CorrelationMeasure::Kendall: prepare_kendall(reference, r); break;
    case CorrelationMeasure::MiBinned: {
      r.values.assign(reference.begin(), reference.end());
      // Members grouped by x bin: a voxel's joint counts are then the counts of its y bins
      // within each group (the kernel's one invocation per voxel).
      std::vector<float> bx(m_count, 0.0f);
      if (!r.constant)
        for (uint32_t m = 0; m < m_count; ++m) bx[m] = float(correlation_bin(reference[m], r.lo, r.hi - r.lo, params.bins));
      r.order = ascending_order(bx);
      r.group.assign(m_count, m_count);
      for (uint32_t p = m_count; p-- > 1;)
        r.group[p - 1] = bx[r.order[p - 1]] == bx[r.order[p]] ? r.group[p] : p;
      r.table.assign(m_count + 1, 0.0f);
      for (uint32_t c = 1; c <= m_count; ++c) r.table[c] = float(std::log(double(c)));
      r.mi_offset = std::log(double(m_count));
      break;
    }
    case CorrelationMeasure::MiKraskov:
    case CorrelationMeasure::MiCoefficient: {
      r.order = ascending_order(reference);
      for (uint32_t m : r.order) r.values.push_back(reference[m]);
      // digamma(1) = -Euler's gamma, digamma(c + 1) = digamma(c) + 1/c.
      std::vector<double> psi(m_count + 1, 0.0);
      psi[1] = -0.57721566490153286061;
      for (uint32_t c = 1; c < m_count; ++c) psi[c + 1] = psi[c] + 1.0 / double(c);
      r.table.assign(psi.begin(), psi.end());
      r.mi_offset = psi[params.k] + psi[m_count];
      break;
    }
  }
  return r;
}

}  // namespace tfm
