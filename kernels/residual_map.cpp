// Pipeline and dispatch recording of the residual-map kernel.
#include "tfmatch/kernels/residual_map.h"

#include "tfmatch/shaders/shader_registry.h"

#include <stdexcept>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/shaders/render_layout.h"

namespace tfm {

namespace {
// Bindings in the order record() lists its buffers.
constexpr auto kResidualBindingCounts =
    gpu::binding_counts({TFM_RESIDUAL_BINDING_REF_FIELD, TFM_RESIDUAL_BINDING_OPT_FIELD, TFM_RESIDUAL_BINDING_REF_TF,
                         TFM_RESIDUAL_BINDING_OPT_TF, TFM_RESIDUAL_BINDING_OUT, TFM_RESIDUAL_BINDING_REF_QUADS,
                         TFM_RESIDUAL_BINDING_OPT_QUADS, TFM_RESIDUAL_BINDING_OUT_QUADS});
}  // namespace

ResidualMapKernel::ResidualMapKernel(Context& ctx, uint64_t range_quads, uint32_t workgroup_size)
    : ctx_(ctx),
      range_quads_(texel_range_quads(ctx, range_quads, "residual_map")),
      workgroup_size_(lane_workgroup_size(ctx, workgroup_size, "residual_map")) {
  pipeline_ = shared_pipeline(ctx, pipeline_desc(nullptr));
}

PipelineDesc ResidualMapKernel::pipeline_desc(const VkExtent3D* image) const {
  PipelineDesc desc;
  desc.shader = image ? "residual_map_image" : "residual_map";
  desc.binding_counts = gpu::to_vector(kResidualBindingCounts);
  desc.binding_kinds = texel_binding_kinds(desc.binding_counts.size(),
                                           {TFM_RESIDUAL_BINDING_REF_TF, TFM_RESIDUAL_BINDING_OPT_TF,
                                            TFM_RESIDUAL_BINDING_REF_QUADS, TFM_RESIDUAL_BINDING_OPT_QUADS,
                                            TFM_RESIDUAL_BINDING_REF_FIELD, TFM_RESIDUAL_BINDING_OPT_FIELD});
  if (image)
    bind_fields_as_images(desc, {TFM_RESIDUAL_BINDING_REF_FIELD, TFM_RESIDUAL_BINDING_OPT_FIELD,
                               TFM_RESIDUAL_BINDING_REF_QUADS, TFM_RESIDUAL_BINDING_OPT_QUADS});
  desc.push_constant_bytes = sizeof(gpu::VoxelPairPush);
  desc.workgroup_size = workgroup_size_;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, workgroup_size_},
                                    {TFM_RESIDUAL_SPEC_IMAGE_NX, image ? image->width : 1u},
                                    {TFM_RESIDUAL_SPEC_IMAGE_NY, image ? image->height : 1u}});
  desc.spirv = shader_spirv(desc.shader);
  return desc;
}

void ResidualMapKernel::check_fields(const DeviceField& ref, const DeviceField& opt, const DeviceField& out) {
  for (const DeviceField* f : {&opt, &out})
    if (f->voxel_count() != ref.voxel_count() || f->chunk_voxels() != ref.chunk_voxels())
      throw std::invalid_argument("residual map: fields differ in size or chunking");
  if (out.format() != FieldFormat::Float32) throw std::invalid_argument("residual map: the output field must be float32");
}

void ResidualMapKernel::check_fields(const ImageFieldView& ref, const ImageFieldView& opt, const DeviceField& out) {
  const uint64_t voxels = check_image_pair(ref, opt, "residual map");
  if (out.voxel_count() != voxels || out.chunk_count() != 1)
    throw std::invalid_argument("residual map: the output must hold the images' " + std::to_string(voxels) +
                                " voxels in one chunk (an image larger than that: copy it, ImageFieldRecorder)");
  if (out.format() != FieldFormat::Float32) throw std::invalid_argument("residual map: the output field must be float32");
}

void ResidualMapKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                               const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                               const Buffer& opt_tf, DeviceField& out) const {
  check_fields(ref, opt, out);
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16 || opt_tf.size() < uint64_t(opt_map.tf_size) * 16)
    throw std::invalid_argument("residual map: TF buffer smaller than its mapping's size");
  const Binding rtf = Binding::texels(ref_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(ref_map.tf_size) * 16);
  const Binding otf = Binding::texels(opt_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(opt_map.tf_size) * 16);
  gpu::VoxelPairPush push = make_voxel_pair_push(ref_map, opt_map);
  for (const QuadRange& r : quad_ranges(ref, range_quads_)) {
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    // Ranges write disjoint voxels: no barrier between them.
    batch.dispatch(*pipeline_,
                   {voxel_texels(ref, r.chunk), voxel_texels(opt, r.chunk), rtf, otf, out.chunk(r.chunk),
                    quad_texels(ref, r), quad_texels(opt, r), out.chunk(r.chunk)},
                   push, {lane_groups(ctx_, workgroup_size_, r.voxels)});
  }
}

void ResidualMapKernel::record(CommandBatch& batch, const ImageFieldView& ref, const ImageFieldView& opt,
                               const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                               const Buffer& opt_tf, DeviceField& out) const {
  check_fields(ref, opt, out);
  const uint64_t voxels = out.voxel_count();
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16 || opt_tf.size() < uint64_t(opt_map.tf_size) * 16)
    throw std::invalid_argument("residual map: TF buffer smaller than its mapping's size");
  SharedPipeline& pipeline = image_pipelines_[{ref.extent.width, ref.extent.height}];
  if (!pipeline) pipeline = shared_pipeline(ctx_, pipeline_desc(&ref.extent));
  const Binding rtf = Binding::texels(ref_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(ref_map.tf_size) * 16);
  const Binding otf = Binding::texels(opt_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(opt_map.tf_size) * 16);
  const Binding r_image = Binding::image(ref.view, ref.layout), o_image = Binding::image(opt.view, opt.layout);
  gpu::VoxelPairPush push = make_voxel_pair_push(ref_map, opt_map);
  for (const QuadRange& r : quad_ranges(std::span<const uint64_t>(&voxels, 1), range_quads_)) {
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    batch.dispatch(*pipeline, {r_image, o_image, rtf, otf, out.chunk(0), r_image, o_image, out.chunk(0)}, push,
                   {lane_groups(ctx_, workgroup_size_, r.voxels)});
  }
}

}  // namespace tfm
