// Helpers shared by the solvers of host/solvers/solver_*.cpp: timing, the Jacobi diagonal from
// the GPU assembly, options several solvers share, and turning an unconstrained solution into a TF.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tfmatch/kernels/visibility_weights.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

double ms_since(std::chrono::steady_clock::time_point t0);

// The problem's assembled system (GPU, deterministic): assembled on the first call and kept in
// p.system, so a solver and the loss measurement of run_optimize share one pass over the voxels.
// Appends an "assemble" phase to `phases` (when given) if this call assembled.
const NormalEquations& assembled_system(VoxelProblem& p, std::vector<PhaseTime>* phases = nullptr);

// The assembled system of a problem (GPU, deterministic) with the absolute regularization weights
// of `options`, and 1 / diag(M + R) per entry (0 where that diagonal is 0: an unreferenced
// entry no iterative solver can move). Throws std::runtime_error when no voxel has data and
// std::invalid_argument for negative weights.
struct JacobiSetup {
  NormalEquations eq;
  Regularization reg;
  std::vector<float> inv_diag;
  double gpu_ms = -1.0;
};
// With `system` (e.g. a weighted one) that system instead of the problem's own.
JacobiSetup jacobi_setup(VoxelProblem& problem, const SolveOptions& options, const NormalEquations* system = nullptr);

// --weights none|visibility and the cameras of the visibility weights (--weight-views,
// --cameras, --seed): the options of the solvers that solve the assembled system (normal-equations, qp).
std::vector<SolverOption> weight_options();

// The voxel weights weight_options() ask for: none for --weights none; for --weights visibility
// those of kernels/visibility_weights.h (the reference rendered over the cameras). Appends the
// phase to out.phases and its numbers (and the choice) to out.details.
std::optional<VisibilityWeights> requested_weights(VoxelProblem& p, const SolverArgs& args, SolverOutput& out);

// The system sum_i w_i (s_i x - b_i)^2 of the problem with `weights`, assembled apart so that
// p.system — the voxel losses run_optimize reports — stays the unweighted one ("assemble
// (weighted)" phase).
NormalEquations weighted_system(VoxelProblem& p, const DeviceField& weights, SolverOutput& out);

// The system a solver of weight_options() solves: assembled_system(p) for --weights none, else
// weighted_system() with the requested weights.
NormalEquations solved_system(VoxelProblem& p, const SolverArgs& args, SolverOutput& out);

// --tolerance and --max-iterations of the CGLS solvers (cgls, eigen-cgls, cuda-cgls).
std::vector<SolverOption> cgls_stop_options();

// cond(M) as a detail: the number, or "inf" for a singular M.
DetailValue cond_detail(double cond);

// Solves the banded system (the "solve" phase) and records in `out` what every normal-equations
// solver reports: the TF, the warnings, the factorization, cond, clamped and unreferenced entries.
SolveResult solve_and_record(const NormalEquations& eq, const SolveOptions& options, SolverOutput& out);

// Entries of the fitted `tf` that no voxel touches (diag(M) = 0) and that the fit left at 0: the
// voxel solvers start there and nothing in the data moves them, so they are transparent black by
// default, not by the data. A warning naming how many (and --smooth, which fills them from their
// neighbours), unless smoothing is on or `warnings` already say so (normal-equations' "M is
// singular"); nullopt otherwise. Every optimize path (whole, streamed, series) asks it.
std::optional<std::string> unreferenced_entries_warning(const NormalEquations& eq, const TransferFunction& tf,
                                                        const SolveOptions& solve,
                                                        const std::vector<std::string>& warnings);

// x (N x 4) clamped to [0,1] as a TF; counts the components that moved.
TransferFunction clamp_to_tf(const Eigen::Matrix<double, Eigen::Dynamic, 4>& x, uint32_t* clamped = nullptr);
// A TF of N float RGBA entries (as read back from the device) clamped to [0,1].
TransferFunction tf_from_floats(const std::vector<float>& rgba, uint32_t* clamped = nullptr);

}  // namespace tfm
