// The TF-sized stages of GPU CGLS (cgls_vectors.comp): one workgroup updates x, p and the
// per-channel scalars in the CGLS state from the accumulators of sparse_gather / sparse_scatter.
#pragma once

#include <cstdint>
#include <memory>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/shaders/solver_layout.h"

namespace tfm {

class Context;

// The preconditioner P = L D L^T (L unit lower bidiagonal) applied to s each iteration.
struct CglsPreconditioner {
  const Buffer* inv_pivot = nullptr;  // N floats: 1 / D_j (0: entry j stays 0)
  const Buffer* lower = nullptr;      // N floats: L_{j+1,j} (the last unused)
  Buffer* z = nullptr;                // N RGBA of scratch, written when bidiagonal
  bool bidiagonal = false;            // false: L = I (Jacobi), z = s / D_j entry by entry
};

struct CglsBuffers {
  const Buffer* s_accum = nullptr;      // signed S^T r slots (signed_accumulator_bytes(N))
  const Buffer* delta_accum = nullptr;  // ||S p||^2 (TFM_GATHER_NORM_SLOTS unsigned slots)
  CglsPreconditioner preconditioner;
  Buffer* x = nullptr;                  // N RGBA
  Buffer* p = nullptr;                  // N RGBA
  Buffer* state = nullptr;              // gpu::CglsState
};

class CglsVectorsKernel {
 public:
  explicit CglsVectorsKernel(Context& ctx);
  // Records one stage (TFM_CGLS_STAGE_*). ridge/smooth are absolute weights; the stop test is
  // ||s||^2 <= tolerance^2 ||s0||^2, or the float32 floor of solver_layout.h under regularization.
  // Throws std::invalid_argument when a buffer is missing or small.
  void record(CommandBatch& batch, uint32_t stage, uint32_t tf_size, float ridge, float smooth, float tolerance,
              const CglsBuffers& buffers) const;

 private:
  SharedPipeline pipeline_;
};

}  // namespace tfm
