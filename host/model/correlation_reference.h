// The reference series of a correlation field, prepared once per field on the host (in double
// where it matters) for the correlation kernels and for the CPU implementation of the same
// methods (host/reference/correlation_cpu.h): its order, tie groups, ranks, centred values and
// the tables of logarithms and digamma values the measures look up.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "tfmatch/model/correlation_measure.h"

namespace tfm {

struct CorrelationReference {
  CorrelationParams params;
  uint32_t members = 0;
  bool has_nan = false;   // NaN (or ±Inf: needs_finite_members) in x: every result NaN, nothing else filled
  bool constant = false;  // min == max
  float lo = 0.0f, hi = 0.0f;
  // Per measure (the kernels' REF_VALUES): pearson x - mean(x) by member; spearman the centred
  // doubled rank 2 rank - (M + 1) by member (an integer); mi-binned x by member; mi-kraskov x
  // sorted ascending (by x-order position).
  std::vector<float> values;
  // kendall, mi-kraskov: the member at each position of x's stable ascending order; mi-binned:
  // of the stable ascending order of x's bins (correlation_bin).
  std::vector<uint32_t> order;
  // kendall: the first position of each position's tie group in that order; mi-binned: the
  // position one past the end of each position's bin (members of one x bin are consecutive).
  std::vector<uint32_t> group;
  // mi-binned: ln c; mi-kraskov, mi-coefficient: digamma(c); for c = 0 .. M (entry 0 unused).
  std::vector<float> table;
  double norm = 0.0;        // pearson: sum (x - mean)^2; spearman: sum (2 rank - (M + 1))^2
  uint64_t tied_pairs = 0;  // kendall: pairs of members tied in x
  double mi_offset = 0.0;   // mi-binned: ln M; mi-kraskov: digamma(k) + digamma(M)
};

// Throws std::invalid_argument when params do not suit reference.size() members.
CorrelationReference prepare_correlation_reference(std::span<const float> reference, const CorrelationParams& params);

// Binned mutual information's bin of `value` among `bins` equal-width bins over a series with
// minimum `lo` and range `range` > 0, in float as the kernel computes it
// (shaders/correlation_mi_binned.comp), so every device and the CPU peer count alike: the largest
// b < bins with b * range <= (value - lo) * bins, each side one correctly rounded product (the
// quotient, which Vulkan lets err by 2.5 ulp, only guesses).
uint32_t correlation_bin(float value, float lo, float range, uint32_t bins);

// The stable ascending order of `values` (indices), NaN-free input.
std::vector<uint32_t> ascending_order(std::span<const float> values);

// Throws std::invalid_argument unless `ens` has values and voxels, `reference` one value per
// member and `params` suit the member count (the checks of every correlation field).
void validate_correlation_inputs(const EnsembleView& ens, std::span<const float> reference,
                                 const CorrelationParams& params);

// Copies the series of voxels [first, first + count) of `ens` to `dst` voxel by voxel (member m of
// the i-th voxel at dst[i * M + m]), reading each member's values in order.
void gather_series(const EnsembleView& ens, uint64_t first, uint32_t count, float* dst);

}  // namespace tfm
