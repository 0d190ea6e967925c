// The GPU pass of iteratively reweighted least squares for the l1 voxel loss (solver `irls`,
// shaders/irls_assemble.comp): at a TF x and weight floors delta, the weighted tridiagonal normal
// equations of each channel and the l1 loss at x, in one pass over the voxels.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/kernels/tf_residual_pass.h"

namespace tfm {

class Context;

// One pass's sums, decoded: for channel c with weights w_i = delta_c / max(|e_ic|, delta_c),
// M_c = S^T W S (diag: n, off: n - 1) and S^T W b_c (rhs: n), and sum_i |e_ic| at x.
struct IrlsSums {
  uint32_t n = 0;
  std::array<std::vector<double>, 4> diag, off, rhs;
  std::array<double, 4> l1{};
  // From the accumulator words of IrlsKernel (irls_accumulator_bytes(n) / 4 of them).
  static IrlsSums from_words(uint32_t n, const std::vector<uint32_t>& words);
};

// The state buffer the pass reads: x (n RGBA entries, in [0,1]) then delta per channel (> 0).
uint64_t irls_state_bytes(uint32_t tf_size);
// Bytes of the pass's accumulators for n entries (TFM_IRLS_ACCUM_WORDS).
uint64_t irls_accumulator_bytes(uint32_t tf_size);

// Adds one pass over (ref, opt) to zeroed accumulators. The same bits for every
// ReductionOptions, chunking and device; throws as Reduction::choose when a forced option does
// not fit the device, std::invalid_argument for buffers too small or mismatched fields.
class IrlsKernel {
 public:
  IrlsKernel(Context& ctx, uint32_t tf_size, ReductionOptions options = {});
  ReductionMode mode() const { return pass_.reduction().mode; }
  bool int64_atomics() const { return pass_.reduction().int64; }
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& state, Buffer& accum) const;

 private:
  TfResidualPass pass_;
};

}  // namespace tfm
