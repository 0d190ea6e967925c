// Settings and per-step constants of the `gradient-descent` solver (exposed for tests that check
// a step by hand).
#pragma once

#include <cstdint>

#include "normal_equations.h"
#include "optimize.h"
#include "solver_layout.h"

namespace tfm {

struct GdOptions {
  bool l1 = false;
  bool adam = true;
  double lr = 0.02;                  // initial step (Adam: TF units; SGD: fraction of a diagonal Newton step)
  uint32_t iterations = 300;
  double beta1 = 0.9, beta2 = 0.999, epsilon = 1e-8;
  double final_lr_fraction = 0.01;   // the cosine schedule ends at this fraction of lr
};

// From --loss, --optimizer, --lr, --iterations; throws std::runtime_error naming a bad flag.
GdOptions gd_options(const SolverSettings& settings);
// Step size of iteration t (1-based): lr (f + (1-f) (1 + cos(pi (t-1)/(T-1))) / 2), f = final fraction.
double gd_learning_rate(const GdOptions& options, uint32_t t);
// Constants of every step (loss normalization by the voxel count V, penalty weights).
gpu::GdUpdatePush gd_push(const GdOptions& options, uint32_t tf_size, uint64_t voxels, const Regularization& reg);
// The push constants of step t: learning rate and Adam bias corrections.
gpu::GdUpdatePush gd_step_push(const gpu::GdUpdatePush& base, const GdOptions& options, uint32_t t);

}  // namespace tfm
