// Pipelines and dispatch of the gradient-descent kernels.
#include "gradient_descent.h"

#include "shader_registry.h"

#include <stdexcept>

#include "context.h"
#include "sparse_ops.h"
#include "voxel_pair.h"

namespace tfm {

static_assert(sizeof(gpu::GdUpdatePush) == 48, "GdUpdatePush must match the GLSL std430 block");

namespace {
// Bindings in the order record() lists each kernel's buffers.
constexpr auto kGradientBindingCounts =
    gpu::binding_counts({TFM_GD_BINDING_REF_FIELD, TFM_GD_BINDING_OPT_FIELD, TFM_GD_BINDING_REF_TF, TFM_GD_BINDING_X,
                         TFM_GD_BINDING_ACCUM, TFM_GD_BINDING_REF_QUADS, TFM_GD_BINDING_OPT_QUADS});
constexpr auto kUpdateBindingCounts =
    gpu::binding_counts({TFM_GD_UPDATE_BINDING_ACCUM, TFM_GD_UPDATE_BINDING_X, TFM_GD_UPDATE_BINDING_M,
                         TFM_GD_UPDATE_BINDING_V, TFM_GD_UPDATE_BINDING_INV_DIAG, TFM_GD_UPDATE_BINDING_GRADIENT});
}  // namespace

uint64_t gd_accumulator_bytes(uint32_t tf_size) { return uint64_t(TFM_GD_ACCUM_WORDS(tf_size)) * sizeof(uint32_t); }

GdGradientKernel::GdGradientKernel(Context& ctx, uint32_t tf_size, bool l1, ReductionOptions options)
    : ctx_(ctx),
      tf_size_(tf_size),
      l1_(l1),
      reduction_(Reduction::choose(ctx, "gd_gradient", tf_size, signed_accumulator_bytes(tf_size), options)) {}

GdGradientKernel::~GdGradientKernel() = default;

const ComputePipeline& GdGradientKernel::pipeline(uint32_t ref_tf_size) const {
  const bool private_cache =
      reduction_.mode == ReductionMode::Private && ref_tf_size <= private_limit(ctx_, kPrivateMaxBins);
  const uint32_t cached = private_cache ? ref_tf_size : 0u;
  auto& slot = pipelines_[cached];
  if (!slot) {
    PipelineDesc desc =
        reduction_.pipeline_desc("gd_gradient", gpu::to_vector(kGradientBindingCounts), sizeof(gpu::VoxelPairPush));
    const bool shared = reduction_.mode == ReductionMode::RunsShared;
    desc.binding_kinds =
        texel_binding_kinds(desc.binding_counts.size(), {TFM_GD_BINDING_REF_QUADS, TFM_GD_BINDING_OPT_QUADS,
                                                          TFM_GD_BINDING_REF_FIELD, TFM_GD_BINDING_OPT_FIELD});
    desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, reduction_.workgroup_size},
                                      {TFM_GD_SPEC_MODE, reduction_.shader_mode()},
                                      {TFM_GD_SPEC_SHARED_SLOTS, shared ? TFM_TF_GRADIENT_SLOTS(tf_size_) : 1u},
                                      {TFM_GD_SPEC_PRIVATE_BINS, reduction_.mode == ReductionMode::Private ? tf_size_ : 0u},
                                      {TFM_GD_SPEC_LOSS_L1, l1_ ? 1u : 0u},
                                      {TFM_GD_SPEC_TF_CACHE, cached}});
    slot = shared_pipeline(ctx_, desc);
  }
  return *slot;
}

void GdGradientKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                              const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                              const Buffer& x, Buffer& accum) const {
  if (ref.voxel_count() != opt.voxel_count() || ref.chunk_voxels() != opt.chunk_voxels())
    throw std::invalid_argument("gd_gradient: fields differ in size or chunking");
  if (opt_map.tf_size != tf_size_) throw std::invalid_argument("gd_gradient: mapping TF size differs from kernel's");
  if (accum.size() < gd_accumulator_bytes(tf_size_) || x.size() < uint64_t(tf_size_) * 16 ||
      ref_tf.size() < uint64_t(ref_map.tf_size) * 16)
    throw std::invalid_argument("gd_gradient: accumulator or TF buffer too small");
  const ComputePipeline& pipe = pipeline(ref_map.tf_size);
  gpu::VoxelPairPush push = make_voxel_pair_push(ref_map, opt_map);
  for (size_t c = 0; c < ref.chunk_count(); ++c) {
    push.voxel_count = static_cast<uint32_t>(ref.chunk_size(c));
    // Chunks fit one texel view (DeviceField): the whole chunk is one range.
    const uint64_t voxels = ref.chunk_size(c);
    const QuadRange whole{c, 0, voxels};
    batch.dispatch(pipe,
                   {voxel_texels(ref, c), voxel_texels(opt, c), ref_tf, x, accum, quad_texels(ref, whole),
                    quad_texels(opt, whole)},
                   push, {reduction_.groups(ctx_, voxels)});
    // Successive chunks add into the same accumulators.
    batch.barrier();
  }
}

GdUpdateKernel::GdUpdateKernel(Context& ctx) {
  PipelineDesc desc;
  desc.shader = "gd_update";
  desc.binding_counts = gpu::to_vector(kUpdateBindingCounts);
  desc.push_constant_bytes = sizeof(gpu::GdUpdatePush);
  desc.workgroup_size = TFM_VECTOR_WORKGROUP;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, TFM_VECTOR_WORKGROUP}});
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = shared_pipeline(ctx, desc);
}

void GdUpdateKernel::record(CommandBatch& batch, const gpu::GdUpdatePush& push, const GdUpdateBuffers& b) const {
  if (!b.accum || !b.x || !b.m || !b.v || !b.inv_diag || !b.gradient)
    throw std::invalid_argument("gd_update: missing buffer");
  const uint64_t rgba = uint64_t(push.tf_size) * 16;
  if (b.accum->size() < gd_accumulator_bytes(push.tf_size) || b.x->size() < rgba || b.m->size() < rgba ||
      b.v->size() < rgba || b.gradient->size() < rgba || b.inv_diag->size() < uint64_t(push.tf_size) * 4)
    throw std::invalid_argument("gd_update: a buffer is smaller than N entries need");
  if (!(push.reg_scale > 0.0f)) throw std::invalid_argument("gd_update: reg_scale must be positive");
  batch.dispatch(*pipeline_, {*b.accum, *b.x, *b.m, *b.v, *b.inv_diag, *b.gradient}, push, {1});
}

}  // namespace tfm
