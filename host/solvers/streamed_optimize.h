// `tfmatch optimize` on volumes larger than memory: both fields read from disk a slab of
// z-slices at a time (host/model/volume_slabs.h), the normal equations assembled slab by slab on
// the device (the same bits as from the whole fields: the assembly's sums are exact fixed-point
// integers), then solved by a solver that works from the assembled system alone. Box-filtered
// copies of both fields, small enough for the report's pictures, are made during the same read.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/ranks.h"
#include "tfmatch/model/volume_slabs.h"
#include "tfmatch/solvers/optimize.h"

namespace tfm {

// The solvers that work from M, S^T b and b^T b alone and so can stream: normal-equations, qp.
const std::vector<std::string>& streaming_solvers();
bool solver_streams(std::string_view solver);

// A range taken from the data (no ref_range / field_range) costs a first pass over the files.
struct StreamedOptimizeRequest : FitSettings {
  VolumeSlabReader* ref = nullptr;
  VolumeSlabReader* field = nullptr;
  // Voxels read per slab and field (rounded down to whole z-slices, at least one slice); 0: from
  // the memory budget (memory_budget.h), at most kDefaultSlabVoxels.
  uint64_t slab_voxels = 0;
  // Voxels of each downsampled copy (ref_preview, field_preview); 0: none made.
  uint64_t preview_voxels = 0;
  // The ranks the run is split over (host/model/ranks.h; null: this process alone). Each reads
  // and assembles its own contiguous range of z-slices (whole preview boxes); the range pass's
  // min/max and counts, the assembly's integer words and the previews' box sums are reduced over
  // ranks, so every rank ends with the same result, bit for bit that of one process. Call it on
  // every rank; a rank's failure makes every rank throw RankFailure.
  Ranks* ranks = nullptr;
};

inline constexpr uint64_t kDefaultSlabVoxels = uint64_t(1) << 24;     // 16 Mi voxels: 64 MiB per field
inline constexpr uint64_t kDefaultPreviewVoxels = uint64_t(1) << 22;  // about 161^3

struct StreamedOptimizeResult {
  OptimizeResult result;  // as run_optimize()'s; the voxel MAE is not measured (NaN)
  // Box-filtered copies: each voxel the mean of the finite values of a factor^3 box of the field
  // (NaN where none), spacing scaled by `preview_factor`, origin at the first box's centre.
  Volume ref_preview, field_preview;
  uint64_t preview_factor = 1;
  uint32_t passes = 1;         // reads of both files: 2 when a range came from the data
  uint64_t slab_slices = 0;    // z-slices per slab
  uint64_t slabs = 0;          // slabs per pass (this rank's)
  uint64_t first_slice = 0, end_slice = 0;  // this rank's z-slices [first, end)
  bool streamed = true;        // false when a reader held its volume in memory (not a streaming format)
};

// Throws as run_optimize() does, and std::runtime_error for a solver that does not stream, grids
// that differ and files that cannot be read ("<file>: ...").
StreamedOptimizeResult run_optimize_streamed(Context& ctx, const StreamedOptimizeRequest& request);

// The normal equations of (ref, field) for the two mappings, assembled `slab_slices` z-slices at a
// time: bit for bit GpuNormalEquations::add() over the whole fields. (What the tests compare.)
NormalEquations assemble_streamed(Context& ctx, VolumeSlabReader& ref, VolumeSlabReader& field,
                                  const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                                  uint64_t slab_slices, uint64_t max_chunk_voxels = 0);
// The same into `gpu` (reset first; its TF size that of opt_map), with the before loss when
// `before_map` is given: its exact 32.32 totals (GpuNormalEquations::fixed_point_slots), which
// add as integers with other fields' (a shared series fit, series_optimize.h).
std::vector<uint64_t> assemble_streamed_slots(Context& ctx, GpuNormalEquations& gpu, VolumeSlabReader& ref,
                                              VolumeSlabReader& field, const FieldMapping& ref_map,
                                              const FieldMapping& opt_map, const Buffer& ref_tf, uint64_t slab_slices,
                                              const FieldMapping* before_map = nullptr, uint64_t max_chunk_voxels = 0);
// The finite min/max and counts of a volume read `slab_slices` z-slices at a time.
FiniteStats streamed_finite_stats(VolumeSlabReader& volume, uint64_t slab_slices);

}  // namespace tfm
