// Pipeline and dispatch recording of the residual-map kernel.
#include "residual_map.h"

#include "shader_registry.h"

#include <stdexcept>

#include "context.h"
#include "render_layout.h"
#include "voxel_pair.h"

namespace tfm {

namespace {
// Bindings in the order record() lists its buffers.
constexpr auto kResidualBindingCounts =
    gpu::binding_counts({TFM_RESIDUAL_BINDING_REF_FIELD, TFM_RESIDUAL_BINDING_OPT_FIELD, TFM_RESIDUAL_BINDING_REF_TF,
                         TFM_RESIDUAL_BINDING_OPT_TF, TFM_RESIDUAL_BINDING_OUT});
}  // namespace

ResidualMapKernel::ResidualMapKernel(Context& ctx) : ctx_(ctx) {
  PipelineDesc desc;
  desc.shader = "residual_map";
  desc.binding_counts = gpu::to_vector(kResidualBindingCounts);
  desc.push_constant_bytes = sizeof(gpu::VoxelPairPush);
  desc.workgroup_size = TFM_RESIDUAL_WORKGROUP;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, TFM_RESIDUAL_WORKGROUP}});
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = std::make_unique<ComputePipeline>(ctx, desc);
}

void ResidualMapKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                               const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                               const Buffer& opt_tf, DeviceField& out) const {
  for (const DeviceField* f : {&opt, static_cast<const DeviceField*>(&out)})
    if (f->voxel_count() != ref.voxel_count() || f->chunk_voxels() != ref.chunk_voxels())
      throw std::invalid_argument("residual map: fields differ in size or chunking");
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16 || opt_tf.size() < uint64_t(opt_map.tf_size) * 16)
    throw std::invalid_argument("residual map: TF buffer smaller than its mapping's size");
  gpu::VoxelPairPush push = make_voxel_pair_push(ref_map, opt_map);
  for (size_t c = 0; c < ref.chunk_count(); ++c) {
    push.voxel_count = static_cast<uint32_t>(ref.chunk_size(c));
    // Chunks write disjoint buffers: no barrier between them.
    batch.dispatch(*pipeline_, {ref.chunk(c), opt.chunk(c), ref_tf, opt_tf, out.chunk(c)}, push,
                   {voxel_groups(ctx_, ref.chunk_size(c))});
  }
}

}  // namespace tfm
