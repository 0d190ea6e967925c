// Correlation fields of reference points: the kernel once or twice, then difference and magnitude.
#include "tfmatch/kernels/correlation_field.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"

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
  for (uint32_t m = 0; m < ens.member_count; ++m) {
    if (std::isnan(s[m]))
      throw std::invalid_argument("the reference point has no data in member " + std::to_string(m) +
                                  " (a NaN or fill value): every correlation with it would be NaN; choose another point");
    // +-Inf is a value: the rank measures order it beyond every finite one; a mean, equal-width
    // bins or neighbour distances over it have none (needs_finite_members).
    if (std::isinf(s[m]) && needs_finite_members(measure))
      throw std::invalid_argument("the reference point's value in member " + std::to_string(m) + " is " +
                                  (s[m] > 0 ? "+inf" : "-inf") + ": " + correlation_measure_name(measure) +
                                  " of a series with an infinite value has none (NaN everywhere); choose another "
                                  "point, or a rank measure (spearman, kendall)");
  }
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

uint64_t correlation_slab_slices(uint32_t members, uint64_t slice_voxels, uint64_t bytes) {
  const uint64_t per_slice = std::max<uint64_t>(1, uint64_t(members) * slice_voxels * sizeof(float));
  return std::max<uint64_t>(1, bytes / per_slice);
}

std::vector<float> correlation_field_streamed(Context& ctx, std::span<VolumeSlabReader* const> members,
                                              const CorrelationRequest& r, uint64_t slab_slices, uint64_t first_slice,
                                              uint64_t end_slice, const CorrelationProgress& progress,
                                              const std::function<void(uint64_t)>& after_slab) {
  CorrelationKernel kernel(ctx);
  return correlation_field_streamed(kernel, members, r, slab_slices, first_slice, end_slice, progress, after_slab);
}

std::vector<float> correlation_field_streamed(CorrelationKernel& kernel, std::span<VolumeSlabReader* const> members,
                                              const CorrelationRequest& r, uint64_t slab_slices, uint64_t first_slice,
                                              uint64_t end_slice, const CorrelationProgress& progress,
                                              const std::function<void(uint64_t)>& after_slab) {
  if (members.empty()) throw std::invalid_argument("correlation_field_streamed: no members");
  const uint32_t m_count = static_cast<uint32_t>(members.size());
  validate_correlation_params(r.params, m_count);
  const Volume& grid = members.front()->grid();
  for (VolumeSlabReader* m : members)
    if (m->grid().dims != grid.dims) throw std::invalid_argument("correlation_field_streamed: members on different grids");
  const uint64_t slice = members.front()->slice_voxels(), nz = grid.dims[2];
  if (end_slice == 0) end_slice = nz;
  if (first_slice > end_slice || end_slice > nz) throw std::invalid_argument("correlation_field_streamed: slices out of range");
  slab_slices = std::max<uint64_t>(1, slab_slices);
  // Reads z-slices [z0, z0 + n) of every member into `buffer`, member-major.
  auto read_members = [&](uint64_t z0, uint64_t n, std::vector<float>& buffer) {
    buffer.resize(size_t(m_count) * n * slice);
    for (uint32_t m = 0; m < m_count; ++m) {
      checkpoint("correlate");
      members[m]->read_slices(z0, n, buffer.data() + size_t(m) * n * slice);
    }
    return EnsembleView{buffer.data(), m_count, n * slice};
  };
  // The reference series, from the slices holding the points, checked as correlation_field() does.
  std::vector<float> buffer;
  auto series_of = [&](uint64_t point) {
    if (point >= grid.voxel_count())
      throw std::invalid_argument("reference voxel " + std::to_string(point) + " is outside the ensemble's " +
                                  std::to_string(grid.voxel_count()) + " voxels");
    const EnsembleView one = read_members(point / slice, 1, buffer);
    check_reference_point(one, point % slice, r.params.measure);
    return ensemble_series(one, point % slice);
  };
  const std::vector<float> first_series = series_of(r.point);
  std::vector<float> second_series;
  if (r.point2) second_series = series_of(*r.point2);

  const uint64_t slabs_voxels = (end_slice - first_slice) * slice;
  check_memory(uint64_t(m_count) * std::min(slab_slices, std::max<uint64_t>(1, end_slice - first_slice)) * slice *
                       sizeof(float) + slabs_voxels * sizeof(float),
               grid.name + ": a slab of " + std::to_string(slab_slices) + " z-slices of " + std::to_string(m_count) +
                   " members and the correlation field");
  std::vector<float> out(slabs_voxels);
  const uint64_t passes = r.point2 ? 2 : 1;
  for (uint64_t z0 = first_slice; z0 < end_slice; z0 += slab_slices) {
    const uint64_t n = std::min(slab_slices, end_slice - z0);
    const EnsembleView slab = read_members(z0, n, buffer);
    const uint64_t at = (z0 - first_slice) * slice;
    // Voxels done of all passes over all slabs: the earlier slabs' passes, this slab's earlier pass.
    auto slab_progress = [&](uint64_t pass) -> CorrelationProgress {
      return [&, pass](uint64_t done, uint64_t) {
        checkpoint("correlate");
        if (progress) progress(passes * at + pass * n * slice + done, passes * slabs_voxels);
      };
    };
    std::vector<float> part = kernel.compute(slab, first_series, r.params, slab_progress(0), r.max_device_bytes);
    if (r.point2) {
      const std::vector<float> second = kernel.compute(slab, second_series, r.params, slab_progress(1), r.max_device_bytes);
      for (size_t i = 0; i < part.size(); ++i) part[i] -= second[i];
    }
    if (r.absolute)
      for (float& v : part) v = std::abs(v);
    std::copy(part.begin(), part.end(), out.begin() + std::ptrdiff_t(at));
    if (after_slab) after_slab(at + n * slice);
  }
  return out;
}

}  // namespace tfm
