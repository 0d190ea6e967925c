// Wrapper of shaders/voxel_loss.comp: per-channel RGBA voxel losses of a TF pair, summed exactly.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <tuple>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/model/field_mapping.h"

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
  // The same from two of a host's 3D images read in place (voxel_pair.h's ImageFieldView): the
  // same bits as from buffers.
  void record(CommandBatch& batch, const ImageFieldView& ref, const ImageFieldView& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf, Buffer& accum,
              const FieldMapping* before_map = nullptr) const;
  // Creates now the pipeline record() takes for fields in buffers, with the loss before
  // optimization or without, so a caller can have it compiled on a thread of its own while other
  // work runs (run_optimize: during the solve). No other call on this object may run meanwhile.
  void prepare(bool with_before) const { pipeline(with_before); }

 private:
  // Compiled on first use; for images per x and y size (specialization constants).
  const ComputePipeline& pipeline(bool with_before, const VkExtent3D* image = nullptr) const;
  // The push block (checked sizes and mappings) of either record().
  gpu::VoxelPairPush push_for(const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                              const Buffer& opt_tf, const Buffer& accum, const FieldMapping* before_map) const;
  Context& ctx_;
  uint64_t range_quads_;
  uint32_t workgroup_size_;
  mutable std::map<std::tuple<bool, uint32_t, uint32_t>, SharedPipeline> pipelines_;
};

}  // namespace tfm
