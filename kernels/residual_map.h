// Wrapper of shaders/residual_map.comp: per voxel || premul(T_r(F_r)) - premul(T_o(F_o)) ||_2
// into a device field chunked like the inputs (NaN in either input gives 0).
#pragma once

#include <memory>

#include "buffer.h"
#include "commands.h"
#include "device_field.h"
#include "pipeline.h"
#include "shared_layout.h"

namespace tfm {

class Context;

class ResidualMapKernel {
 public:
  // Dispatches per range of at most `range_quads` quads (texel_range_quads) in workgroups of
  // lane_workgroup_size(ctx, workgroup_size) (voxel_pair.h); tests force both.
  explicit ResidualMapKernel(Context& ctx, uint64_t range_quads = 0, uint32_t workgroup_size = 0);
  // Records one dispatch per range. `ref_map`/`opt_map` carry each TF's size. Throws
  // std::invalid_argument when the three fields differ in size or chunking.
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf, DeviceField& out) const;

 private:
  Context& ctx_;
  uint64_t range_quads_;
  uint32_t workgroup_size_;
  std::unique_ptr<ComputePipeline> pipeline_;
};

}  // namespace tfm
