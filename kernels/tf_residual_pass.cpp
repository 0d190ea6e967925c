// Pipelines and dispatch of the tf_residual.glsl kernels (gd_gradient, irls_assemble).
#include "tfmatch/kernels/tf_residual_pass.h"

#include <stdexcept>
#include <string>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/shaders/solver_layout.h"

namespace tfm {

namespace {
// The kernels share binding and specialization numbers: gd_gradient's name them.
static_assert(TFM_IRLS_BINDING_REF_FIELD == TFM_GD_BINDING_REF_FIELD && TFM_IRLS_BINDING_OPT_FIELD == TFM_GD_BINDING_OPT_FIELD &&
              TFM_IRLS_BINDING_REF_TF == TFM_GD_BINDING_REF_TF && TFM_IRLS_BINDING_STATE == TFM_GD_BINDING_X &&
              TFM_IRLS_BINDING_ACCUM == TFM_GD_BINDING_ACCUM && TFM_IRLS_BINDING_REF_QUADS == TFM_GD_BINDING_REF_QUADS &&
              TFM_IRLS_BINDING_OPT_QUADS == TFM_GD_BINDING_OPT_QUADS);
static_assert(TFM_IRLS_SPEC_MODE == TFM_GD_SPEC_MODE && TFM_IRLS_SPEC_SHARED_SLOTS == TFM_GD_SPEC_SHARED_SLOTS &&
              TFM_IRLS_SPEC_PRIVATE_BINS == TFM_GD_SPEC_PRIVATE_BINS && TFM_IRLS_SPEC_TF_CACHE == TFM_GD_SPEC_TF_CACHE);
// Bindings in the order record() lists the buffers.
constexpr auto kBindingCounts =
    gpu::binding_counts({TFM_GD_BINDING_REF_FIELD, TFM_GD_BINDING_OPT_FIELD, TFM_GD_BINDING_REF_TF, TFM_GD_BINDING_X,
                         TFM_GD_BINDING_ACCUM, TFM_GD_BINDING_REF_QUADS, TFM_GD_BINDING_OPT_QUADS});
}  // namespace

TfResidualPass::TfResidualPass(Context& ctx, uint32_t tf_size, TfResidualShader shader, ReductionOptions options)
    : ctx_(ctx),
      tf_size_(tf_size),
      shader_(std::move(shader)),
      reduction_(Reduction::choose(ctx, shader_.name, tf_size, uint64_t(shader_.shared_slots) * gpu::kFixedSlotBytes,
                                   options, shader_.private_max_bins)) {
  reduction_.lane_loops_per_quad = TFM_RESIDUAL_WALK_LOOPS_PER_QUAD;
}

const ComputePipeline& TfResidualPass::pipeline(uint32_t ref_tf_size) const {
  const bool private_cache =
      reduction_.mode == ReductionMode::Private && ref_tf_size <= private_limit(ctx_, kPrivateMaxBins);
  const uint32_t cached = private_cache ? ref_tf_size : 0u;
  auto& slot = pipelines_[cached];
  if (!slot) {
    PipelineDesc desc =
        reduction_.pipeline_desc(shader_.name, gpu::to_vector(kBindingCounts), sizeof(gpu::VoxelPairPush));
    const bool shared = reduction_.mode == ReductionMode::RunsShared;
    desc.binding_kinds =
        texel_binding_kinds(desc.binding_counts.size(), {TFM_GD_BINDING_REF_QUADS, TFM_GD_BINDING_OPT_QUADS,
                                                          TFM_GD_BINDING_REF_FIELD, TFM_GD_BINDING_OPT_FIELD});
    std::vector<std::pair<uint32_t, uint32_t>> spec = {
        {TFM_SPEC_WORKGROUP_X, reduction_.workgroup_size},
        {TFM_GD_SPEC_MODE, reduction_.shader_mode()},
        {TFM_GD_SPEC_SHARED_SLOTS, shared ? shader_.shared_slots : 1u},
        {TFM_GD_SPEC_PRIVATE_BINS, reduction_.mode == ReductionMode::Private ? tf_size_ : 0u},
        {TFM_GD_SPEC_TF_CACHE, cached}};
    spec.insert(spec.end(), shader_.extra_specialization.begin(), shader_.extra_specialization.end());
    desc.specialization = gpu::by_id(spec);
    slot = shared_pipeline(ctx_, desc);
  }
  return *slot;
}

void TfResidualPass::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                            const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                            const Buffer& x, Buffer& accum) const {
  const std::string name = shader_.name;
  if (ref.voxel_count() != opt.voxel_count() || ref.chunk_voxels() != opt.chunk_voxels())
    throw std::invalid_argument(name + ": fields differ in size or chunking");
  if (opt_map.tf_size != tf_size_) throw std::invalid_argument(name + ": mapping TF size differs from kernel's");
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16) throw std::invalid_argument(name + ": reference TF buffer too small");
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

}  // namespace tfm
