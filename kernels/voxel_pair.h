// The two voxel-pair kernels (normal-equation assembly and voxel loss): small wrappers that
// create the pipeline and record one dispatch per field chunk.
#pragma once

#include <array>
#include <cstdint>
#include <memory>

#include "buffer.h"
#include "commands.h"
#include "device_field.h"
#include "pipeline.h"
#include "shared_layout.h"

namespace tfm {

class Context;

gpu::VoxelPairPush make_voxel_pair_push(const FieldMapping& ref, const FieldMapping& opt);

// Adds M, S^T b, b^T b and the voxel count of (ref, opt) to a 32.32 fixed-point accumulator
// buffer of TFM_ASSEMBLE_SLOTS(N) slots. Accumulates in workgroup-shared memory when the device
// has room for the slots, else straight to the buffer (`force_global` selects that path).
// Each invocation sums `run` contiguous voxels in registers between flushes (0: the default
// TFM_ASSEMBLE_RUN, or the environment variable TFMATCH_ASSEMBLE_RUN for tuning on a device).
// The result is bit-identical for every path and run length.
class AssembleNormalEquationsKernel {
 public:
  AssembleNormalEquationsKernel(Context& ctx, uint32_t tf_size, bool force_global = false, uint32_t run = 0);
  uint32_t tf_size() const { return tf_size_; }
  uint32_t slots() const;
  bool uses_shared_memory() const { return use_shared_; }
  // Records one dispatch per chunk (barriers between them) into `batch`.
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, Buffer& accum) const;

 private:
  Context& ctx_;
  uint32_t tf_size_;
  bool use_shared_;
  std::unique_ptr<ComputePipeline> pipeline_;
};

// Adds per-channel sums of squared and absolute colour differences and the voxel count to a
// TFM_LOSS_SLOTS-slot fixed-point accumulator.
class VoxelLossKernel {
 public:
  explicit VoxelLossKernel(Context& ctx);
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf, Buffer& accum) const;

 private:
  Context& ctx_;
  std::unique_ptr<ComputePipeline> pipeline_;
};

// Workgroups for a 1-D voxel kernel over `voxels` (each invocation loops over ~32 voxels).
uint32_t voxel_groups(const Context& ctx, uint64_t voxels);
// Decodes `slots` 32.32 fixed-point accumulators read back as 2*slots uint32 words.
std::vector<double> decode_fixed_point(const std::vector<uint32_t>& words);

}  // namespace tfm
