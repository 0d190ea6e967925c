// Wrapper of shaders/voxel_loss.comp: per-channel RGBA voxel losses of a TF pair, summed exactly.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "buffer.h"
#include "commands.h"
#include "device_field.h"
#include "field_mapping.h"
#include "pipeline.h"
#include "reduction.h"
#include "voxel_pair.h"

namespace tfm {

class Context;

// Adds per-channel sums of squared and absolute colour differences and the voxel count to a
// TFM_LOSS_SLOTS-slot fixed-point accumulator; with `before_map` (the second field mapped onto
// the reference TF's entries) also the loss before optimization, in the same pass, to slots
// TFM_LOSS_SLOTS.. 2 TFM_LOSS_SLOTS - 1. Dispatches per range of at most `range_quads` quads
// (texel_range_quads) in workgroups of lane_workgroup_size(ctx, workgroup_size). Every choice
// gives the same bits (tests force splits and sizes).
class VoxelLossKernel {
 public:
  explicit VoxelLossKernel(Context& ctx, uint64_t range_quads = 0, uint32_t workgroup_size = 0);
  ~VoxelLossKernel();
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf, Buffer& accum,
              const FieldMapping* before_map = nullptr) const;

 private:
  const ComputePipeline& pipeline(bool with_before) const;  // compiled on first use
  Context& ctx_;
  uint64_t range_quads_;
  uint32_t workgroup_size_;
  mutable std::array<std::unique_ptr<ComputePipeline>, 2> pipelines_;
};

}  // namespace tfm
