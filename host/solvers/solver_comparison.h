// `tfmatch solvers`: every solver on one problem, side by side like the paper's Table 1: time
// per phase, iterations, final voxel loss, largest difference to the exact box-constrained (QP)
// solution, and how each treats the box 0 <= x <= 1 (with the KKT residual of its result).
#pragma once

#include <functional>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "tfmatch/solvers/optimize.h"

namespace tfm {

struct ComparisonRow {
  std::string solver;
  std::string error;                 // non-empty: the solver threw; other fields are unset
  std::vector<PhaseTime> phases;     // the solver's own phases (no upload or loss passes)
  double total_ms = 0.0;             // sum of the phases' wall times
  int64_t iterations = -1;           // -1: not an iterative solver
  double rmse = 0.0, mae = 0.0;      // voxel loss of the returned TF (GPU, RGBA)
  TransferFunction tf;               // the solver's result
  double max_diff_to_qp = 0.0;       // largest |x - x_qp| over entries and channels
  std::string box;                   // "enforced", "projected" or "clamped K"
  double kkt = 0.0;                  // box KKT residual of the returned TF (TF units), 0 = optimal
  std::vector<std::string> warnings;
  Details details;
};

struct ComparisonResult {
  std::string device;
  uint64_t voxels = 0, voxels_with_data = 0;
  uint32_t tf_size = 0;
  double rmse_reference_tf = 0.0;    // the field shown with the reference TF
  std::vector<ComparisonRow> rows;   // the QP reference first
  // Solvers of the default list that cannot run here (Solver::unavailable: the CUDA solvers
  // without a CUDA device), with why: left out rather than listed as failed.
  std::vector<std::pair<std::string, std::string>> skipped;

  void print_table(std::ostream& os) const;  // JSON: host/report/result_json.h
};

// The runs of a comparison: `solvers` (empty: every solver that is not image-based and can run
// here, those that cannot in `skipped` with why), `qp` first, and the settings each gets (the
// options of settings.extra it declares, checked). A solver named explicitly always runs (and
// fails with its reason). Throws std::runtime_error for an unknown solver, an option none of them
// has, or a bad value.
struct ComparisonPlan {
  std::vector<std::string> solvers;
  std::vector<SolverSettings> settings;
  std::vector<std::pair<std::string, std::string>> skipped;
};
ComparisonPlan plan_comparison(const SolverSettings& settings, std::vector<std::string> solvers);

// Runs `solvers` (empty: every solver that is not image-based, i.e. all but diffdvr, and can run
// here: plan_comparison) on the
// problem of `request` (its solver field is ignored), `qp` always first as the reference. Each
// solver gets the options of request.settings.extra it declares. Throws std::runtime_error
// before running anything for an unknown solver, an option none of them has, or a bad value.
// A solver that throws while solving gets an error row; the QP reference throwing ends the
// comparison (std::runtime_error).
// `on_row`, when given, sees each row as soon as its solver is done (progress on long runs).
ComparisonResult compare_solvers(Context& ctx, const OptimizeRequest& request, std::vector<std::string> solvers,
                                 const std::function<void(const ComparisonRow&, size_t index, size_t count)>& on_row = {});

}  // namespace tfm
