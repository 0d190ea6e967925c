// Wrapper of shaders/residual_map.comp: per voxel || premul(T_r(F_r)) - premul(T_o(F_o)) ||_2
// into a device field chunked like the inputs (NaN in either input gives 0).
#pragma once

#include <map>
#include <memory>
#include <utility>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/shaders/shared_layout.h"

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
  // The same from two of a host's 3D images read in place (voxel_pair.h's ImageFieldView) into
  // `out`, a float32 field of the volume's voxels in one chunk: the same bits as from buffers.
  // Throws std::invalid_argument for image views that do not match or an output of another size
  // or of several chunks.
  void record(CommandBatch& batch, const ImageFieldView& ref, const ImageFieldView& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf, DeviceField& out) const;
  // record()'s checks of the fields alone (std::invalid_argument), for callers that must refuse
  // before they record anything (the recorders of recording.h).
  static void check_fields(const DeviceField& ref, const DeviceField& opt, const DeviceField& out);
  static void check_fields(const ImageFieldView& ref, const ImageFieldView& opt, const DeviceField& out);

 private:
  PipelineDesc pipeline_desc(const VkExtent3D* image) const;
  Context& ctx_;
  uint64_t range_quads_;
  uint32_t workgroup_size_;
  SharedPipeline pipeline_;
  // The image variant per x and y size (specialization constants), made when first recorded.
  mutable std::map<std::pair<uint32_t, uint32_t>, SharedPipeline> image_pipelines_;
};

}  // namespace tfm
