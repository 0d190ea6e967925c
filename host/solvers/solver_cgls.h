// The GPU CGLS loop (solver `cgls`) as a typed call: matrix-free, preconditioned CGLS on the
// voxel least-squares problem, four channels at once.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "tfmatch/kernels/device_cgls.h"
#include "tfmatch/solvers/normal_equations.h"
#include "tfmatch/solvers/solver.h"

namespace tfm {

struct CglsGpuOptions {
  // Stop a channel when ||S^T r - R x|| <= tolerance ||S^T b||; in (0, 1).
  double tolerance = 1e-6;
  uint32_t max_iterations = 1000;  // >= 1
  SolveOptions regularization;     // ridge and smooth (relative weights); factorization unused
  uint64_t max_chunk_voxels = 0;   // voxel vectors in blocks of at most this many voxels; 0: device limit
  // Weighted least squares (--weights): per-voxel weights (a float32 field chunked as the problem's
  // fields) and their weighted system (weighted_system(), for the preconditioner and the
  // regularization's scale). Both or neither.
  const DeviceField* weights = nullptr;
  const NormalEquations* weighted_system = nullptr;
};

struct CglsGpuResult {
  TransferFunction tf;                          // the iterate, clamped to [0,1]
  std::array<uint32_t, 4> iterations{};         // per RGBA channel
  std::array<double, 4> relative_residual{};    // ||S^T r - R x|| / ||S^T b|| per channel at the end
  // The float32 floor of the relative residual per channel, u (ridge + 4 smooth) ||x|| / ||S^T b||
  // (u = 2^-24; 0 without regularization): how large R's action on x's rounding can make the
  // residual. A channel stops when the tolerance is out of reach and its residual in P^-1's norm
  // is down to that rounding's share there (cgls_vectors.comp), which a smooth error never is.
  std::array<double, 4> residual_floor{};
  uint32_t clamped_values = 0;                  // components moved into [0,1]
  uint32_t voxel_chunks = 0;                    // blocks of the voxel vectors
  std::vector<PhaseTime> phases;                // "setup", "iterate"
  uint32_t max_iterations() const;              // over channels
  double worst_relative_residual() const;       // over channels
  std::array<bool, 4> capped{};                 // still running at max_iterations: met neither stop test
  bool any_capped() const;
};

// The preconditioner of the `cgls` solver for M + R (R: absolute weights). Without smoothing,
// Jacobi, diag(M + R), as the paper's CGLS (unreferenced entries without a ridge stay 0). With
// smoothing, diag(M) + R: its L D L^T inverts the smoothing exactly, so the preconditioned system
// keeps the condition of the data's Jacobi scaling however heavy the smoothing (Jacobi alone
// stopped at 1000 iterations from --smooth 100 on). Throws std::invalid_argument for a system
// without voxels or with fewer than 2 entries.
CglsFactors cgls_preconditioner(const NormalEquations& eq, const Regularization& reg);

// Runs CGLS from x = 0 on the GPU until every channel meets the tolerance (or its float32 floor) or
// max_iterations.
// Deterministic: the same problem gives the same bits. Throws std::invalid_argument for options
// out of range or negative weights, std::runtime_error when no voxel has data in both fields,
// VulkanError for device failures.
CglsGpuResult solve_cgls_gpu(VoxelProblem& problem, const CglsGpuOptions& options);

}  // namespace tfm
