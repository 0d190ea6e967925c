// The `normal-equations` solver as a typed call: M and S^T b assembled on the GPU, then the host
// tridiagonal solve (normal_equations.h).
#pragma once

#include <vector>

#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

struct NormalEquationsGpuResult {
  SolveResult solve;               // TF clamped to [0,1], cond(M), warnings, ...
  std::vector<PhaseTime> phases;   // "assemble" (GPU time measured), "solve"
};

// Assembles the problem's normal equations on the GPU (deterministic) and solves them with
// `options`. Throws std::runtime_error when no voxel has data in both fields, VulkanError for
// device failures.
NormalEquationsGpuResult solve_normal_equations_gpu(VoxelProblem& problem, const SolveOptions& options);

}  // namespace tfm
