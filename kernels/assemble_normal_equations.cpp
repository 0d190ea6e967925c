// Pipelines and dispatches of the normal-equation assembly (kernels/assemble_normal_equations.h).
#include "assemble_normal_equations.h"

#include <algorithm>
#include <stdexcept>

#include "context.h"
#include "shader_registry.h"

namespace tfm {

namespace {
// Bindings in the order record() lists the buffers.
constexpr auto kAssembleBindingCounts =
    gpu::binding_counts({TFM_ASSEMBLE_BINDING_REF_FIELD, TFM_ASSEMBLE_BINDING_OPT_FIELD, TFM_ASSEMBLE_BINDING_REF_TF,
                         TFM_ASSEMBLE_BINDING_ACCUM, TFM_ASSEMBLE_BINDING_REF_QUADS, TFM_ASSEMBLE_BINDING_OPT_QUADS});
}  // namespace

namespace {
// The bin terms a voxel adds (shaders/assemble_normal_equations.comp).
constexpr uint32_t kBinTerms = 11;
}  // namespace

std::vector<AssembleNormalEquationsKernel::TermPass> assemble_term_passes(ReductionMode mode, uint32_t tf_size,
                                                                          uint32_t slots) {
  if (mode != ReductionMode::Private) return {{0, kBinTerms}};
  // As many terms per pass as keep a lane's histogram within `slots`, spread evenly over the
  // fewest passes.
  const uint32_t per_pass = std::clamp<uint32_t>(slots / tf_size, 1, kBinTerms);
  const uint32_t count = (kBinTerms + per_pass - 1) / per_pass;
  std::vector<AssembleNormalEquationsKernel::TermPass> passes;
  for (uint32_t p = 0, first = 0; p < count; ++p) {
    const uint32_t terms = (kBinTerms - first) / (count - p);
    passes.push_back({first, terms});
    first += terms;
  }
  return passes;
}

AssembleNormalEquationsKernel::AssembleNormalEquationsKernel(Context& ctx, uint32_t tf_size, ReductionOptions options)
    : ctx_(ctx),
      tf_size_(tf_size),
      reduction_(Reduction::choose(ctx, "assemble", tf_size, uint64_t(TFM_ASSEMBLE_SLOTS(tf_size)) * gpu::kFixedSlotBytes,
                                   options, kAssemblePrivateMaxBins)),
      passes_(assemble_term_passes(reduction_.mode, tf_size, private_limit(ctx, kPrivateHistogramSlots))),
      range_quads_(texel_range_quads(ctx, options.range_quads, "assemble")) {
  // Pipelines are compiled on first use: a kernel records either variant (pipelines()).
}

const std::vector<std::unique_ptr<ComputePipeline>>& AssembleNormalEquationsKernel::pipelines(bool with_before) const {
  std::vector<std::unique_ptr<ComputePipeline>>& out = pipelines_[with_before ? 1 : 0];
  if (!out.empty()) return out;
  for (const TermPass& pass : passes_) {
    PipelineDesc desc = reduction_.pipeline_desc("assemble_normal_equations", gpu::to_vector(kAssembleBindingCounts),
                                                 sizeof(gpu::VoxelPairPush));
    desc.binding_kinds = texel_binding_kinds(
        desc.binding_counts.size(),
        {TFM_ASSEMBLE_BINDING_REF_TF, TFM_ASSEMBLE_BINDING_REF_QUADS, TFM_ASSEMBLE_BINDING_OPT_QUADS,
         TFM_ASSEMBLE_BINDING_REF_FIELD, TFM_ASSEMBLE_BINDING_OPT_FIELD});
    desc.specialization = gpu::by_id(
        {{TFM_SPEC_WORKGROUP_X, reduction_.workgroup_size},
         {TFM_ASSEMBLE_SPEC_MODE, reduction_.shader_mode()},
         {TFM_ASSEMBLE_SPEC_SHARED_SLOTS, reduction_.mode == ReductionMode::RunsShared ? slots() : 1u},
         {TFM_ASSEMBLE_SPEC_PRIVATE_BINS, reduction_.mode == ReductionMode::Private ? tf_size_ : 0u},
         {TFM_ASSEMBLE_SPEC_TERM_FIRST, pass.first},
         {TFM_ASSEMBLE_SPEC_TERM_COUNT, pass.count},
         {TFM_ASSEMBLE_SPEC_WITH_BEFORE, with_before ? 1u : 0u}});
    out.push_back(std::make_unique<ComputePipeline>(ctx_, desc));
  }
  return out;
}

AssembleNormalEquationsKernel::~AssembleNormalEquationsKernel() = default;

uint32_t AssembleNormalEquationsKernel::slots() const { return TFM_ASSEMBLE_SLOTS(tf_size_); }

void AssembleNormalEquationsKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                                           const FieldMapping& ref_map, const FieldMapping& opt_map,
                                           const Buffer& ref_tf, Buffer& accum, const FieldMapping* before_map) const {
  check_voxel_pair(ref, opt, "assemble");
  if (opt_map.tf_size != tf_size_) throw std::invalid_argument("assemble: mapping TF size differs from kernel's");
  if (accum.size() < slots() * gpu::kFixedSlotBytes)
    throw std::invalid_argument("assemble: accumulator buffer too small");
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16)
    throw std::invalid_argument("assemble: reference TF buffer holds fewer entries than its mapping");
  const Binding tf = Binding::texels(ref_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(ref_map.tf_size) * 16);
  gpu::VoxelPairPush push = make_voxel_pair_push(ref_map, opt_map);
  if (before_map) {
    if (before_map->tf_size != ref_map.tf_size)
      throw std::invalid_argument("assemble: the before mapping must map onto the reference TF's entries");
    push.before_lo = before_map->lo;
    push.before_scale = before_map->scale;
  }
  const auto& passes = pipelines(before_map != nullptr);
  for (const QuadRange& r : quad_ranges(ref, range_quads_)) {  // one dispatch per range and pass
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    for (const auto& pipe : passes) {
      batch.dispatch(*pipe,
                     {voxel_texels(ref, r.chunk), voxel_texels(opt, r.chunk), tf, accum, quad_texels(ref, r),
                      quad_texels(opt, r)},
                     push, {reduction_.groups(ctx_, r.voxels)});
      // Successive dispatches add into the same accumulators.
      batch.barrier();
    }
  }
}

}  // namespace tfm
