// The CPU implementation of correlation fields with the kernels' fast methods (Kendall by merge
// sort inversion counting, Spearman by sort and binary search, Kraskov by a band search in x
// order), on all cores: the benchmark's peer of the GPU kernels. Each voxel is independent, so
// the threads take blocks of voxels from a shared counter and the result does not depend on
// their number.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <thread>

#include "tfmatch/model/correlation_reference.h"
#include "tfmatch/reference/correlation_cpu.h"
#include "tfmatch/shaders/correlation_layout.h"

namespace tfm {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Working memory of one thread.
struct Scratch {
  std::vector<float> series, a, b, c;
  std::vector<uint32_t> joint, marginal;
};

// Stable bottom-up merge sort of v (tmp: scratch of the same size); returns the pairs p < q with
// v[p] > v[q]. The sorted values end in v.
uint64_t sort_counting_inversions(std::vector<float>& v, std::vector<float>& tmp) {
  const size_t n = v.size();
  uint64_t inversions = 0;
  for (size_t w = 1; w < n; w *= 2) {
    for (size_t b0 = 0; b0 < n; b0 += 2 * w) {
      const size_t mid = std::min(n, b0 + w), end = std::min(n, b0 + 2 * w);
      size_t i = b0, j = mid, d = b0;
      while (i < mid || j < end) {
        if (j >= end || (i < mid && v[i] <= v[j])) {
          tmp[d++] = v[i++];
        } else {
          inversions += mid - i;
          tmp[d++] = v[j++];
        }
      }
    }
    v.swap(tmp);
  }
  return inversions;
}

// Pairs of equal neighbours in sorted runs [first, end) of v: t(t-1)/2 per run of t equal values.
uint64_t tied_pairs(const std::vector<float>& v, size_t first, size_t end) {
  uint64_t pairs = 0, run = 0;
  for (size_t q = first + 1; q < end; ++q) {
    run = v[q] == v[q - 1] ? run + 1 : 0;
    pairs += run;
  }
  return pairs;
}

float pearson(const CorrelationReference& r, const float* y) {
  double mean = 0.0;
  for (uint32_t m = 0; m < r.members; ++m) mean += y[m];
  mean /= r.members;
  double sxy = 0.0, syy = 0.0;
  for (uint32_t m = 0; m < r.members; ++m) {
    sxy += double(r.values[m]) * (y[m] - mean);
    syy += (y[m] - mean) * (y[m] - mean);
  }
  return float(std::clamp(sxy / (std::sqrt(r.norm) * std::sqrt(syy)), -1.0, 1.0));
}

float spearman(const CorrelationReference& r, const float* y, Scratch& s) {
  const uint32_t n = r.members;
  s.a.assign(y, y + n);
  std::sort(s.a.begin(), s.a.end());
  int64_t sxy = 0, syy = 0;
  for (uint32_t m = 0; m < n; ++m) {
    const auto lo = std::lower_bound(s.a.begin(), s.a.end(), y[m]), hi = std::upper_bound(lo, s.a.end(), y[m]);
    // Doubled fractional rank lower + upper + 1, centred.
    const int64_t c = int64_t((lo - s.a.begin()) + (hi - s.a.begin()) + 1) - int64_t(n + 1);
    sxy += int64_t(r.values[m]) * c;
    syy += c * c;
  }
  return float(std::clamp(double(sxy) / (std::sqrt(r.norm) * std::sqrt(double(syy))), -1.0, 1.0));
}

float kendall(const CorrelationReference& r, const float* y, Scratch& s) {
  const uint32_t n = r.members;
  s.a.resize(n);
  s.b.resize(n);
  for (uint32_t p = 0; p < n; ++p) s.a[p] = y[r.order[p]];
  // Knight: within each x tie group order by y; its equal neighbours are tied in both.
  uint64_t both = 0;
  for (uint32_t p = 0; p < n;) {
    uint32_t end = p + 1;
    while (end < n && r.group[end] == p) ++end;
    std::sort(s.a.begin() + p, s.a.begin() + end);
    both += tied_pairs(s.a, p, end);
    p = end;
  }
  const uint64_t discordant = sort_counting_inversions(s.a, s.b);
  const uint64_t y_ties = tied_pairs(s.a, 0, n);
  const double n0 = double(n) * double(n - 1) / 2.0, n1 = double(r.tied_pairs);
  const double numerator = n0 - n1 - double(y_ties) + double(both) - 2.0 * double(discordant);
  return float(std::clamp(numerator / (std::sqrt(n0 - n1) * std::sqrt(n0 - double(y_ties))), -1.0, 1.0));
}

float mi_binned(const CorrelationReference& r, const float* y, float y_lo, float y_hi, Scratch& s) {
  const uint32_t n = r.members, bins = r.params.bins;
  const float x_range = r.hi - r.lo, y_range = y_hi - y_lo;
  s.joint.assign(size_t(bins) * bins, 0);
  s.marginal.assign(2 * size_t(bins), 0);
  for (uint32_t m = 0; m < n; ++m) {
    const uint32_t bx = correlation_bin(r.values[m], r.lo, x_range, bins), by = correlation_bin(y[m], y_lo, y_range, bins);
    ++s.joint[bx * bins + by];
    ++s.marginal[bx];
    ++s.marginal[bins + by];
  }
  double sum = 0.0;
  for (uint32_t m = 0; m < n; ++m) {
    const uint32_t bx = correlation_bin(r.values[m], r.lo, x_range, bins), by = correlation_bin(y[m], y_lo, y_range, bins);
    sum += double(r.table[s.joint[bx * bins + by]]) - r.table[s.marginal[bx]] - r.table[s.marginal[bins + by]];
  }
  return float(std::max(r.mi_offset + sum / n, 0.0));
}

// Distance from point p to its k-th nearest neighbour (max-norm) by the kernel's band search.
float kth_neighbour_distance(const std::vector<float>& xs, const std::vector<float>& yx, uint32_t p, uint32_t k) {
  std::array<float, TFM_CORR_MAX_K> best{};
  uint32_t found = 0;
  const uint32_t n = uint32_t(xs.size());
  uint32_t left = p, right = p + 1;
  while (left > 0 || right < n) {
    const float dl = left > 0 ? xs[p] - xs[left - 1] : std::numeric_limits<float>::infinity();
    const float dr = right < n ? xs[right] - xs[p] : std::numeric_limits<float>::infinity();
    const bool go_left = left > 0 && (right >= n || dl <= dr);
    const float dx = go_left ? dl : dr;
    if (found == k && dx >= best[k - 1]) break;
    const uint32_t q = go_left ? --left : right++;
    const float d = std::max(dx, std::abs(yx[q] - yx[p]));
    if (found < k || d < best[k - 1]) {
      uint32_t j = found < k ? found++ : k - 1;
      for (; j > 0 && best[j - 1] > d; --j) best[j] = best[j - 1];
      best[j] = d;
    }
  }
  return best[k - 1];
}

// Values of sorted v with |v - c| < eps (v - c rounded in float, as the search computes it).
uint32_t count_within(const std::vector<float>& v, float c, float eps) {
  const auto first = std::partition_point(v.begin(), v.end(), [&](float a) { return !(a - c > -eps); });
  const auto end = std::partition_point(first, v.end(), [&](float a) { return !(a - c >= eps); });
  return uint32_t(end - first);
}

float mi_kraskov(const CorrelationReference& r, const float* y, Scratch& s) {
  const uint32_t n = r.members, k = r.params.k;
  s.b.resize(n);
  for (uint32_t p = 0; p < n; ++p) s.b[p] = y[r.order[p]];
  s.c.assign(y, y + n);
  std::sort(s.c.begin(), s.c.end());
  s.a.assign(r.values.begin(), r.values.end());  // x sorted
  double sum = 0.0;
  for (uint32_t p = 0; p < n; ++p) {
    const float eps = kth_neighbour_distance(s.a, s.b, p, k);
    const uint32_t self = eps > 0.0f ? 1 : 0;
    sum += double(r.table[count_within(s.a, s.a[p], eps) - self + 1]) + r.table[count_within(s.c, s.b[p], eps) - self + 1];
  }
  const double mi = r.mi_offset - sum / n;
  return float(r.params.measure == CorrelationMeasure::MiCoefficient ? std::sqrt(1.0 - std::exp(-2.0 * std::max(mi, 0.0)))
                                                                      : mi);
}

float voxel_value(const CorrelationReference& r, const float* y, Scratch& s) {
  const auto [lo, hi] = std::minmax_element(y, y + r.members);
  const bool finite = needs_finite_members(r.params.measure);
  if (std::any_of(y, y + r.members, [&](float v) { return std::isnan(v) || (finite && std::isinf(v)); })) return kNaN;
  const bool mi = r.params.measure == CorrelationMeasure::MiBinned || r.params.measure == CorrelationMeasure::MiKraskov ||
                  r.params.measure == CorrelationMeasure::MiCoefficient;
  if (r.constant || *lo == *hi) return mi ? 0.0f : kNaN;
  switch (r.params.measure) {
    case CorrelationMeasure::Pearson: return pearson(r, y);
    case CorrelationMeasure::Spearman: return spearman(r, y, s);
    case CorrelationMeasure::Kendall: return kendall(r, y, s);
    case CorrelationMeasure::MiBinned: return mi_binned(r, y, *lo, *hi, s);
    case CorrelationMeasure::MiKraskov:
    case CorrelationMeasure::MiCoefficient: return mi_kraskov(r, y, s);
  }
  return kNaN;
}

}  // namespace

std::vector<float> correlation_field_cpu(const EnsembleView& ens, std::span<const float> reference,
                                         const CorrelationParams& params, unsigned threads) {
  validate_correlation_inputs(ens, reference, params);
  const CorrelationReference ref = prepare_correlation_reference(reference, params);
  std::vector<float> out(ens.voxel_count, kNaN);
  if (ref.has_nan) return out;
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  // Blocks of voxels gathered series by series (gather_series reads each member's values in order).
  constexpr uint32_t kBlock = 64;
  std::atomic<uint64_t> next{0};
  auto work = [&] {
    Scratch s;
    std::vector<float> block(size_t(kBlock) * ens.member_count);
    for (uint64_t v0; (v0 = next.fetch_add(kBlock)) < ens.voxel_count;) {
      const uint32_t count = uint32_t(std::min<uint64_t>(kBlock, ens.voxel_count - v0));
      gather_series(ens, v0, count, block.data());
      for (uint32_t i = 0; i < count; ++i) out[v0 + i] = voxel_value(ref, block.data() + size_t(i) * ens.member_count, s);
    }
  };
  {
    // jthreads: joined however this block is left (a failed start, an exception on this thread),
    // before `out` and the counter they use go away.
    std::vector<std::jthread> pool;
    for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
    work();
  }
  return out;
}

}  // namespace tfm
