// The GPU gradient-descent loop (solver `gradient-descent`) as a typed call, and the per-step
// constants it pushes (exposed for tests that check a step by hand).
#pragma once

#include <cstdint>
#include <vector>

#include "tfmatch/shaders/solver_layout.h"
#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

struct GradientDescentOptions {
  bool l1 = false;                   // least absolute deviations instead of least squares
  bool adam = true;                  // Adam; false: Jacobi-scaled SGD
  double lr = 0.02;                  // initial step (Adam: TF units; SGD: fraction of a diagonal Newton step, 1 typical)
  uint32_t iterations = 300;
  double beta1 = 0.9, beta2 = 0.999, epsilon = 1e-8;
  double final_lr_fraction = 0.01;   // the cosine schedule ends at this fraction of lr
  SolveOptions regularization;       // ridge and smooth (relative weights); factorization unused
};

struct GradientDescentResult {
  TransferFunction tf;               // the last iterate (in [0,1]: every iterate is projected)
  // Mean over voxels and RGBA of e^2 (l2) or |e| (l1) at the last gradient evaluation.
  double last_loss = 0.0;
  // l2 only (else -1): the largest |x - x*| over entries and channels, x* the exact minimizer of
  // the same regularized loss in the box (solve_box_constrained, O(N) on the assembled system).
  // A fixed number of gradient steps may end far from it: heavy smoothing makes the problem stiff
  // (on the demo pair, 300 Adam steps end 0.54 away at --smooth 1e4).
  double distance_to_optimum = -1.0;
  std::vector<PhaseTime> phases;     // "setup", "iterate"
};

// Projected gradient descent on the GPU from x = 0 (unreferenced entries stay 0), matrix-free,
// with a cosine learning-rate schedule. Deterministic. Throws std::invalid_argument for options
// out of range (lr not finite and > 0, no iterations) or negative weights, std::runtime_error
// when no voxel has data in both fields, VulkanError for device failures.
GradientDescentResult solve_gradient_descent_gpu(VoxelProblem& problem, const GradientDescentOptions& options);

// Step size of iteration t (1-based): lr (f + (1-f) (1 + cos(pi (t-1)/(T-1))) / 2), f = final fraction.
double gd_learning_rate(const GradientDescentOptions& options, uint32_t t);
// Constants of every step (loss normalization by the voxel count V, penalty weights).
gpu::GdUpdatePush gd_push(const GradientDescentOptions& options, uint32_t tf_size, uint64_t voxels,
                          const Regularization& reg);
// The push constants of step t: learning rate and Adam bias corrections.
gpu::GdUpdatePush gd_step_push(const gpu::GdUpdatePush& base, const GradientDescentOptions& options, uint32_t t);

}  // namespace tfm
