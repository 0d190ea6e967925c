// The optimization pipeline behind `tfmatch optimize` and `tfmatch demo`: resolve ranges, put
// both fields on the device, run the chosen solver (solver.h), measure voxel loss before and after
// from the assembled system (the solver's, when it assembled one).
#pragma once

#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/model/volume.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

// What a fit of a second field's TF to a reference is asked, however the fields are read (in
// memory: run_optimize; slab by slab: run_optimize_streamed; many fields: run_optimize_series).
struct FitSettings {
  TransferFunction ref_tf;
  std::optional<FieldRange> ref_range;    // user ranges; default: TF file's range, then finite min/max
  std::optional<FieldRange> field_range;
  uint32_t tf_size = 64;
  std::string solver = "normal-equations";
  SolverSettings settings;                // options of `solver` (checked before anything is loaded)
  uint64_t max_chunk_voxels = 0;          // device chunks (tests force splits); 0: device limit
  // A range not from the field leaving > 95 % of its values outside is an error unless this.
  bool allow_out_of_range = false;
};

struct OptimizeRequest : FitSettings {
  const Volume* ref = nullptr;
  const Volume* field = nullptr;
  // Also measure the voxel mean absolute error before and after (VoxelLoss::absolute): one pass
  // over the voxels per TF. The RMSE needs none: it follows from the assembled system.
  bool voxel_mae = false;
};

struct OptimizeResult {
  TransferFunction tf;                    // optimized, with range = field range
  std::string solver;
  FieldRange ref_range, field_range;
  VoxelLoss before;                       // field with the reference TF
  VoxelLoss after;                        // field with the optimized TF
  // (both from M, S^T b, b^T b; absolute differences only with OptimizeRequest::voxel_mae)
  uint64_t voxels_total = 0;
  std::vector<PhaseTime> phases;
  std::vector<std::string> warnings;     // ranges not fitting the fields, then the solver's
  Details details;                        // the solver's (JSON: host/report/result_json.h)
  std::string device;

  void print_summary(std::ostream& os) const;
};

// Throws std::runtime_error for unusable input (grids differ, constant field, unknown solver, a
// solver option the solver does not have or a bad value of one: see parse_solver_args).
OptimizeResult run_optimize(Context& ctx, const OptimizeRequest& request);

}  // namespace tfm
