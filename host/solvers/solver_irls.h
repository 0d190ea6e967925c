// Least absolute deviations by iteratively reweighted least squares on the GPU (solver `irls`):
// the robust fit of gradient descent's l1 loss in a few dozen passes over the voxels instead of
// hundreds of gradient steps, each pass a weighted assembly (kernels/irls.h) and four small
// box-constrained tridiagonal solves on the host (box_qp.h).
#pragma once

#include <cstdint>
#include <vector>

#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

struct IrlsOptions {
  // Residuals below delta (colour units) are weighted as delta: the passes minimize the Huber loss
  // of this threshold, which is within V delta / 2 of the l1 loss (V voxels).
  double delta = 1e-4;
  // The threshold starts at 1/shrink after the least-squares start and is divided by shrink each
  // pass down to delta (continuation: large thresholds converge fast and lead to the small one).
  double shrink = 4.0;
  // Stop once the threshold is at delta and a pass lowered the objective by less than this
  // fraction of it.
  double tolerance = 1e-5;
  // Over-relaxation once the threshold is at delta (adaptive, as in adaptive overrelaxed EM,
  // Salakhutdinov & Roweis 2003): the next iterate is x + beta (x_mm - x), x_mm the pass's
  // box-constrained solve, kept in the box; beta starts at 1 and grows by overrelax_growth after
  // every pass that lowered the objective, up to overrelax_max; a pass that did not lower it is
  // dropped and the passes go on from the plain step of the best iterate, beta back at 1. The
  // passes at a fixed threshold converge linearly (each gains ~0.8 of the one before on the demo
  // pair), so steps longer than the majorizer's reach a third fewer passes. overrelax_max = 1:
  // plain majorize-minimize.
  double overrelax_max = 8.0;
  double overrelax_growth = 1.5;
  uint32_t max_iterations = 100;  // passes over the voxels, the first included
  SolveOptions regularization;    // ridge and smooth (relative weights); factorization unused
};

struct IrlsResult {
  TransferFunction tf;          // the iterate of the lowest objective, in [0,1]
  // Objective at tf: (sum over voxels and RGBA of |e| + sum_c x_c^T R x_c) / (4 V), gradient
  // descent's l1 loss.
  double loss = 0.0;
  std::vector<double> history;  // the objective at each pass's iterate
  uint32_t rejected = 0;        // over-relaxed iterates that did not lower the objective
  uint32_t iterations = 0;      // passes
  bool converged = false;       // false: max_iterations ended it
  std::vector<PhaseTime> phases;  // "assemble" (unless the problem had its system), "setup" (the least-squares start), "iterate"
};

// From the box-constrained least-squares solution, passes of weights delta_k / max(|e|, delta_k)
// per voxel and channel (Huber majorization), each followed by the exact box-constrained solve
// of the weighted system. Deterministic (fixed-point sums, double host solves). Throws
// std::invalid_argument for options out of range, std::runtime_error when no voxel has data,
// VulkanError for device failures.
IrlsResult solve_irls_gpu(VoxelProblem& problem, const IrlsOptions& options);

}  // namespace tfm
