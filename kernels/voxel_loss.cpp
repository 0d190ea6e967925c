// Pipelines and dispatches of the voxel loss (kernels/voxel_loss.h).
#include "tfmatch/kernels/voxel_loss.h"

#include <stdexcept>

#include "tfmatch/engine/context.h"
#include "tfmatch/shaders/shader_registry.h"

namespace tfm {

namespace {
// Bindings in the order record() lists the buffers.
constexpr auto kLossBindingCounts =
    gpu::binding_counts({TFM_LOSS_BINDING_REF_FIELD, TFM_LOSS_BINDING_OPT_FIELD, TFM_LOSS_BINDING_REF_TF,
                         TFM_LOSS_BINDING_OPT_TF, TFM_LOSS_BINDING_ACCUM, TFM_LOSS_BINDING_REF_QUADS,
                         TFM_LOSS_BINDING_OPT_QUADS});
}  // namespace

VoxelLossKernel::VoxelLossKernel(Context& ctx, uint64_t range_quads, uint32_t workgroup_size)
    : ctx_(ctx),
      range_quads_(texel_range_quads(ctx, range_quads, "voxel_loss")),
      workgroup_size_(lane_workgroup_size(ctx, workgroup_size, "voxel_loss")) {}

VoxelLossKernel::~VoxelLossKernel() = default;

const ComputePipeline& VoxelLossKernel::pipeline(bool with_before, const VkExtent3D* image) const {
  SharedPipeline& p =
      pipelines_[{with_before, image ? image->width : 0u, image ? image->height : 0u}];
  if (p) return *p;
  PipelineDesc desc;
  desc.shader = image ? "voxel_loss_image" : "voxel_loss";
  desc.binding_counts = gpu::to_vector(kLossBindingCounts);
  desc.binding_kinds = texel_binding_kinds(desc.binding_counts.size(),
                                           {TFM_LOSS_BINDING_REF_TF, TFM_LOSS_BINDING_OPT_TF, TFM_LOSS_BINDING_REF_QUADS,
                                            TFM_LOSS_BINDING_OPT_QUADS, TFM_LOSS_BINDING_REF_FIELD,
                                            TFM_LOSS_BINDING_OPT_FIELD});
  if (image)
    bind_fields_as_images(desc, {TFM_LOSS_BINDING_REF_FIELD, TFM_LOSS_BINDING_OPT_FIELD,
                               TFM_LOSS_BINDING_REF_QUADS, TFM_LOSS_BINDING_OPT_QUADS});
  desc.push_constant_bytes = sizeof(gpu::VoxelPairPush);
  desc.workgroup_size = workgroup_size_;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, workgroup_size_},
                                    {TFM_LOSS_SPEC_WITH_BEFORE, with_before ? 1u : 0u},
                                    {TFM_LOSS_SPEC_IMAGE_NX, image ? image->width : 1u},
                                    {TFM_LOSS_SPEC_IMAGE_NY, image ? image->height : 1u}});
  desc.spirv = shader_spirv(desc.shader);
  p = shared_pipeline(ctx_, desc);
  return *p;
}

gpu::VoxelPairPush VoxelLossKernel::push_for(const FieldMapping& ref_map, const FieldMapping& opt_map,
                                             const Buffer& ref_tf, const Buffer& opt_tf, const Buffer& accum,
                                             const FieldMapping* before_map) const {
  if (accum.size() < (before_map ? 2 : 1) * TFM_LOSS_SLOTS * gpu::kFixedSlotBytes)
    throw std::invalid_argument("voxel loss: accumulator too small");
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16 || opt_tf.size() < uint64_t(opt_map.tf_size) * 16)
    throw std::invalid_argument("voxel loss: a TF buffer holds fewer entries than its mapping");
  gpu::VoxelPairPush push = make_voxel_pair_push(ref_map, opt_map);
  if (before_map) {
    if (before_map->tf_size != ref_map.tf_size)
      throw std::invalid_argument("voxel loss: the before mapping must map onto the reference TF's entries");
    push.before_lo = before_map->lo;
    push.before_scale = before_map->scale;
  }
  return push;
}

void VoxelLossKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                             const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                             const Buffer& opt_tf, Buffer& accum, const FieldMapping* before_map) const {
  check_voxel_pair(ref, opt, "voxel_loss");
  gpu::VoxelPairPush push = push_for(ref_map, opt_map, ref_tf, opt_tf, accum, before_map);
  const Binding rtf = Binding::texels(ref_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(ref_map.tf_size) * 16);
  const Binding otf = Binding::texels(opt_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(opt_map.tf_size) * 16);
  const ComputePipeline& pipe = pipeline(before_map != nullptr);
  for (const QuadRange& r : quad_ranges(ref, range_quads_)) {
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    batch.dispatch(pipe,
                   {voxel_texels(ref, r.chunk), voxel_texels(opt, r.chunk), rtf, otf, accum, quad_texels(ref, r),
                    quad_texels(opt, r)},
                   push, {lane_groups(ctx_, workgroup_size_, r.voxels)});
    // Successive ranges add into the same accumulators.
    batch.barrier();
  }
}

void VoxelLossKernel::record(CommandBatch& batch, const ImageFieldView& ref, const ImageFieldView& opt,
                             const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                             const Buffer& opt_tf, Buffer& accum, const FieldMapping* before_map) const {
  const uint64_t voxels = check_image_pair(ref, opt, "voxel_loss");
  gpu::VoxelPairPush push = push_for(ref_map, opt_map, ref_tf, opt_tf, accum, before_map);
  const Binding rtf = Binding::texels(ref_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(ref_map.tf_size) * 16);
  const Binding otf = Binding::texels(opt_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(opt_map.tf_size) * 16);
  const Binding r_image = Binding::image(ref.view, ref.layout), o_image = Binding::image(opt.view, opt.layout);
  const ComputePipeline& pipe = pipeline(before_map != nullptr, &ref.extent);
  for (const QuadRange& r : quad_ranges(std::span<const uint64_t>(&voxels, 1), range_quads_)) {
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    batch.dispatch(pipe, {r_image, o_image, rtf, otf, accum, r_image, o_image}, push,
                   {lane_groups(ctx_, workgroup_size_, r.voxels)});
    batch.barrier();
  }
}

}  // namespace tfm
