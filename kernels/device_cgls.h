// Preconditioned CGLS on the device over prepared voxel vectors (sparse_prepare's b in the
// vectors' RGBA, which then hold the residual r): the start (s0 = S^T b and the INIT stage) and
// one iteration (||S p||^2, alpha and x, r -= alpha S p with s = S^T r, beta and p), recorded as
// the `cgls` solver and the self-test run them. Owns the TF-sized device state: x, p, the
// preconditioner's factors and scratch, the accumulators and the per-channel scalars.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/cgls_vectors.h"
#include "tfmatch/kernels/sparse_ops.h"

namespace tfm {

class Context;

// The preconditioner P = L D L^T of N entries: inv_pivot[j] = 1 / D_j (0: entry j stays 0) and,
// unless L = I, lower[j] = L_{j+1,j} (N - 1 entries).
struct CglsFactors {
  std::vector<float> inv_pivot;
  std::vector<float> lower;  // empty: L = I (Jacobi)
};

// Absolute weights of R = ridge I + smooth D^T D, and the stop test ||s|| <= tolerance ||s0||.
struct CglsWeights {
  float ridge = 0.0f;
  float smooth = 0.0f;
  float tolerance = 1e-6f;
};

class DeviceCgls {
 public:
  // Throws std::invalid_argument when the factors do not have N (and N - 1) entries.
  DeviceCgls(Context& ctx, uint32_t tf_size, const CglsFactors& factors, const CglsWeights& weights);

  // After sparse_prepare has written the vectors (its writes need no barrier of the caller's:
  // this begins with one): s0 = S^T b, x = 0, p = P^-1 s0.
  void record_start(CommandBatch& batch, VoxelVectors& vectors);
  // One iteration of every running channel; stopped channels keep x.
  void record_iteration(CommandBatch& batch, VoxelVectors& vectors);

  gpu::CglsState read_state(Context& ctx) const;
  std::vector<float> read_x(Context& ctx) const;  // N RGBA

 private:
  uint32_t n_;
  CglsWeights weights_;
  bool bidiagonal_;
  Buffer inv_pivot_, lower_, z_, s_accum_, delta_accum_, x_, p_, state_;
  SparseGatherKernel gather_;
  SparseScatterKernel scatter_, scatter_update_;
  CglsVectorsKernel vectors_;

  CglsBuffers buffers();
  void record_stage(CommandBatch& batch, uint32_t stage);
};

}  // namespace tfm
