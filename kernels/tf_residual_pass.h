// The pipelines and dispatches of the kernels built on shaders/tf_residual.glsl, which reduce
// per-voxel terms of the residual T_o(F_o) - b at a TF x into TF-entry slots: gd_gradient
// (gradient descent) and irls_assemble (iteratively reweighted least squares). Both take the
// same bindings (the two fields as voxel and quad texels, the reference TF, x, the accumulators)
// and the same leading specialization constants; each kernel wraps one pass object.
#pragma once

#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/reduction.h"

namespace tfm {

class Context;

struct TfResidualShader {
  const char* name = nullptr;          // the shader (its _int64 build when the reduction uses 64-bit atomics)
  uint32_t shared_slots = 0;           // workgroup-shared accumulator slots for N entries (RUNS_SHARED)
  uint32_t private_max_bins = 0;       // most TF entries of the private-histogram path on a CPU device
  // Specialization constants after the common ones (workgroup, mode, shared slots, private bins,
  // reference-TF cache), as (constant_id, value).
  std::vector<std::pair<uint32_t, uint32_t>> extra_specialization;
};

class TfResidualPass {
 public:
  // Throws as Reduction::choose when a forced option does not fit the device.
  TfResidualPass(Context& ctx, uint32_t tf_size, TfResidualShader shader, ReductionOptions options);
  const Reduction& reduction() const { return reduction_; }
  uint32_t tf_size() const { return tf_size_; }
  // Adds every chunk of (ref, opt) into `accum` (one dispatch per chunk, each ended by a
  // barrier). Throws std::invalid_argument naming the shader when the fields differ in size or
  // chunking, the mapping's TF size is not the kernel's or the reference TF's buffer is too small;
  // the caller checks x and the accumulators, whose sizes are its own.
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& x, Buffer& accum) const;

 private:
  // The pipeline for a reference TF of `ref_tf_size` entries (CPU devices copy it per lane).
  const ComputePipeline& pipeline(uint32_t ref_tf_size) const;
  Context& ctx_;
  uint32_t tf_size_;
  TfResidualShader shader_;
  Reduction reduction_;
  mutable std::map<uint32_t, SharedPipeline> pipelines_;
};

}  // namespace tfm
