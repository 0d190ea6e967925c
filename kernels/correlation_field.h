// Correlation fields as scientists ask for them: the measure of one reference point against every
// voxel, or the difference of two reference points' fields, optionally as magnitudes; checked so
// that a bad reference point is an error, not a field of NaN.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "context.h"
#include "correlation.h"
#include "ensemble.h"

namespace tfm {

struct CorrelationRequest {
  CorrelationParams params;
  uint64_t point = 0;                 // linear voxel index of the reference point
  std::optional<uint64_t> point2;     // with it: corr(point) - corr(point2)
  bool absolute = false;              // |result| (after the difference)
  uint64_t max_device_bytes = 0;      // CorrelationKernel::compute's chunk budget (0: default)
};

// Computes the field on the device. Throws std::invalid_argument when a reference point lies
// outside the ensemble, has no data (NaN) in some member, or (for pearson, spearman, kendall) is
// constant over the members, and for params that do not suit the member count.
// `progress` sees voxels done of all voxels (twice the grid with point2).
std::vector<float> correlation_field(Context& ctx, const EnsembleView& ens, const CorrelationRequest& request,
                                     const CorrelationProgress& progress = {});

// Throws std::runtime_error "<ensemble>: N member(s); a correlation over members needs at least
// 3" for an ensemble too small for any measure.
void check_correlation_members(const Ensemble& ens);

// Throws std::invalid_argument (the reasons above) unless `voxel` can be a reference point.
void check_reference_point(const EnsembleView& ens, uint64_t voxel, CorrelationMeasure measure);

}  // namespace tfm
