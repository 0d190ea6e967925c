// `tfmatch solvers`: every solver on one problem, side by side like the paper's Table 1: time
// per phase, iterations, final voxel loss, largest difference to the exact box-constrained (QP)
// solution, and how each treats the box 0 <= x <= 1 (with the KKT residual of its result).
#pragma once

#include <functional>
#include <ostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "optimize.h"

namespace tfm {

struct ComparisonRow {
  std::string solver;
  std::string error;                 // non-empty: the solver threw; other fields are unset
  std::vector<PhaseTime> phases;     // the solver's own phases (no upload or loss passes)
  double total_ms = 0.0;             // sum of the phases' wall times
  int64_t iterations = -1;           // -1: not an iterative solver
  double rmse = 0.0, mae = 0.0;      // voxel loss of the returned TF (GPU, RGBA)
  double max_diff_to_qp = 0.0;       // largest |x - x_qp| over entries and channels
  std::string box;                   // "enforced", "projected" or "clamped K"
  double kkt = 0.0;                  // box KKT residual of the returned TF (TF units), 0 = optimal
  std::vector<std::string> warnings;
  nlohmann::json details;
};

struct ComparisonResult {
  std::string device;
  uint64_t voxels = 0, voxels_with_data = 0;
  uint32_t tf_size = 0;
  double rmse_reference_tf = 0.0;    // the field shown with the reference TF
  std::vector<ComparisonRow> rows;   // the QP reference first

  nlohmann::json to_json() const;
  void print_table(std::ostream& os) const;
};

// Runs `solvers` (empty: every registered voxel solver, i.e. all but diffdvr) on the problem of `request` (its solver field is
// ignored), `qp` always first as the reference. A solver that throws gets an error row; the QP
// reference throwing ends the comparison (std::runtime_error).
// `on_row`, when given, sees each row as soon as its solver is done (progress on long runs).
ComparisonResult compare_solvers(Context& ctx, const OptimizeRequest& request, std::vector<std::string> solvers,
                                 const std::function<void(const ComparisonRow&, size_t index, size_t count)>& on_row = {});

}  // namespace tfm
