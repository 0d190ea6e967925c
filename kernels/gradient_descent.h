// Kernels of GPU gradient descent on the voxel objective: gd_gradient (loss and gradient sums
// over the voxels, l2 or l1) and gd_update (one SGD or Adam step on the TF, projected to [0,1]).
#pragma once

#include <cstdint>
#include <memory>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/kernels/tf_residual_pass.h"
#include "tfmatch/shaders/solver_layout.h"

namespace tfm {

class Context;

// Adds the loss per channel and the signed gradient sums of (ref, opt) at the TF x to an
// accumulator of TFM_GD_ACCUM_WORDS(N) words: gradient slots as in sparse_scatter, then the loss.
// The same bits for every ReductionOptions; throws as Reduction::choose when a forced one does
// not fit the device.
class GdGradientKernel {
 public:
  GdGradientKernel(Context& ctx, uint32_t tf_size, bool l1, ReductionOptions options = {});
  ReductionMode mode() const { return pass_.reduction().mode; }
  bool int64_atomics() const { return pass_.reduction().int64; }
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& x, Buffer& accum) const;

 private:
  TfResidualPass pass_;
};

struct GdUpdateBuffers {
  const Buffer* accum = nullptr;     // from GdGradientKernel
  Buffer* x = nullptr;               // N RGBA, updated in place
  Buffer* m = nullptr;               // Adam first moment (N RGBA)
  Buffer* v = nullptr;               // Adam second moment (N RGBA)
  const Buffer* inv_diag = nullptr;  // N floats: 1 / diag(M + R), 0 for unreferenced entries
  Buffer* gradient = nullptr;        // N RGBA, receives the gradient of this step
};

class GdUpdateKernel {
 public:
  explicit GdUpdateKernel(Context& ctx);
  void record(CommandBatch& batch, const gpu::GdUpdatePush& push, const GdUpdateBuffers& buffers) const;

 private:
  SharedPipeline pipeline_;
};

// Bytes of the gradient-descent accumulator for N entries (TFM_GD_ACCUM_WORDS).
uint64_t gd_accumulator_bytes(uint32_t tf_size);

}  // namespace tfm
