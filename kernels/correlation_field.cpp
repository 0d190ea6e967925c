// Correlation fields of reference points: the kernel once or twice, then difference and magnitude.
#include "correlation_field.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "cancellation.h"

namespace tfm {

void check_correlation_members(const Ensemble& ens) {
  if (ens.member_count < 3)
    throw std::runtime_error(ens.grid.name + ": " + std::to_string(ens.member_count) +
                             " member(s); a correlation over members needs at least 3");
}

void check_reference_point(const EnsembleView& ens, uint64_t voxel, CorrelationMeasure measure) {
  if (voxel >= ens.voxel_count)
    throw std::invalid_argument("reference voxel " + std::to_string(voxel) + " is outside the ensemble's " +
                                std::to_string(ens.voxel_count) + " voxels");
  const std::vector<float> s = ensemble_series(ens, voxel);
  for (uint32_t m = 0; m < ens.member_count; ++m)
    if (!std::isfinite(s[m]))
      throw std::invalid_argument("the reference point has no data in member " + std::to_string(m) +
                                  " (a NaN or fill value): every correlation with it would be NaN; choose another point");
  const bool needs_variance = measure == CorrelationMeasure::Pearson || measure == CorrelationMeasure::Spearman ||
                              measure == CorrelationMeasure::Kendall;
  bool constant = true;
  for (uint32_t m = 1; m < ens.member_count; ++m) constant &= s[m] == s[0];
  if (needs_variance && constant)
    throw std::invalid_argument(std::string("the reference point's value is the same in every member (") + std::to_string(s[0]) +
                                "): " + correlation_measure_name(measure) + " needs variance; choose another point");
}

std::vector<float> correlation_field(Context& ctx, const EnsembleView& ens, const CorrelationRequest& r,
                                     const CorrelationProgress& progress) {
  validate_correlation_params(r.params, ens.member_count);
  check_reference_point(ens, r.point, r.params.measure);
  if (r.point2) check_reference_point(ens, *r.point2, r.params.measure);
  CorrelationKernel kernel(ctx);
  const uint64_t passes = r.point2 ? 2 : 1;
  // Called after every chunk of voxels: a cancellation stops the field between chunks.
  auto pass_progress = [&](uint64_t pass) -> CorrelationProgress {
    return [&, pass](uint64_t done, uint64_t total) {
      checkpoint("correlate");
      if (progress) progress(pass * total + done, passes * total);
    };
  };
  std::vector<float> out =
      kernel.compute(ens, ensemble_series(ens, r.point), r.params, pass_progress(0), r.max_device_bytes);
  if (r.point2) {
    const std::vector<float> second =
        kernel.compute(ens, ensemble_series(ens, *r.point2), r.params, pass_progress(1), r.max_device_bytes);
    for (size_t i = 0; i < out.size(); ++i) out[i] -= second[i];
  }
  if (r.absolute)
    for (float& v : out) v = std::abs(v);
  return out;
}

}  // namespace tfm
