// Correlation fields as scientists ask for them: the measure of one reference point against every
// voxel, or the difference of two reference points' fields, optionally as magnitudes; checked so
// that a bad reference point is an error, not a field of NaN.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/model/ensemble.h"
#include "tfmatch/model/volume_slabs.h"

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

// The same field from members read a slab of z-slices at a time (each member a VolumeSlabReader,
// all on one grid), for the z-slices [first_slice, end_slice) only (a rank's share; end_slice 0:
// all): the reference points' series come from their own slices first, then each slab of all
// members is read member-major and its voxels computed. Every voxel's value depends on its series
// and the reference series alone, so the result is correlation_field()'s bits for those voxels.
// Host memory: the members' slab (members x slab_slices x slice voxels floats, checked against
// the memory budget) and the result. Throws as correlation_field() does and as the readers do.
// `after_slab(voxels done)` runs after each slab (an MPI job's ranks meet there to combine their
// progress: docs/mpi.md).
std::vector<float> correlation_field_streamed(Context& ctx, std::span<VolumeSlabReader* const> members,
                                              const CorrelationRequest& request, uint64_t slab_slices,
                                              uint64_t first_slice = 0, uint64_t end_slice = 0,
                                              const CorrelationProgress& progress = {},
                                              const std::function<void(uint64_t)>& after_slab = {});
// The same with the caller's kernel: one whose pipeline prepare() built before the caller measured
// the memory it sizes the slabs from.
std::vector<float> correlation_field_streamed(CorrelationKernel& kernel, std::span<VolumeSlabReader* const> members,
                                              const CorrelationRequest& request, uint64_t slab_slices,
                                              uint64_t first_slice = 0, uint64_t end_slice = 0,
                                              const CorrelationProgress& progress = {},
                                              const std::function<void(uint64_t)>& after_slab = {});
// Slices per slab for `members` members of `slice_voxels` voxels within `bytes` of host memory
// (at least 1).
uint64_t correlation_slab_slices(uint32_t members, uint64_t slice_voxels, uint64_t bytes);

// Throws std::runtime_error "<ensemble>: N member(s); a correlation over members needs at least
// 3" for an ensemble too small for any measure.
void check_correlation_members(const Ensemble& ens);

// Throws std::invalid_argument (the reasons above) unless `voxel` can be a reference point.
void check_reference_point(const EnsembleView& ens, uint64_t voxel, CorrelationMeasure measure);

}  // namespace tfm
