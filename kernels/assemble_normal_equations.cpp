// Pipelines and dispatches of the normal-equation assembly (kernels/assemble_normal_equations.h).
#include "tfmatch/kernels/assemble_normal_equations.h"

#include <algorithm>
#include <stdexcept>

#include "tfmatch/engine/context.h"
#include "tfmatch/shaders/shader_registry.h"

namespace tfm {

namespace {
// Bindings in the order record() lists the buffers.
constexpr auto kAssembleBindingCounts =
    gpu::binding_counts({TFM_ASSEMBLE_BINDING_REF_FIELD, TFM_ASSEMBLE_BINDING_OPT_FIELD, TFM_ASSEMBLE_BINDING_REF_TF,
                         TFM_ASSEMBLE_BINDING_ACCUM, TFM_ASSEMBLE_BINDING_REF_QUADS, TFM_ASSEMBLE_BINDING_OPT_QUADS});
// The weighted variant's: the same, then the weights' voxels and quads.
constexpr auto kWeightedBindingCounts =
    gpu::binding_counts({TFM_ASSEMBLE_BINDING_REF_FIELD, TFM_ASSEMBLE_BINDING_OPT_FIELD, TFM_ASSEMBLE_BINDING_REF_TF,
                         TFM_ASSEMBLE_BINDING_ACCUM, TFM_ASSEMBLE_BINDING_REF_QUADS, TFM_ASSEMBLE_BINDING_OPT_QUADS,
                         TFM_ASSEMBLE_BINDING_WEIGHTS, TFM_ASSEMBLE_BINDING_WEIGHT_QUADS});
}  // namespace

namespace {
// The bin terms a voxel adds (shaders/assemble_normal_equations.comp).
constexpr uint32_t kBinTerms = 11;
}  // namespace

std::vector<AssembleNormalEquationsKernel::TermPass> assemble_term_passes(ReductionMode mode, uint32_t tf_size,
                                                                          uint32_t slots) {
  if (mode != ReductionMode::Private) return {{0, kBinTerms}};
  // The fewest passes that keep a lane's histogram within `slots`, each of the same number of
  // terms but the last (the passes are rows of one dispatch of one pipeline: row y adds the
  // terms from y times that number), spread as evenly as that allows.
  const uint32_t most = std::clamp<uint32_t>(slots / tf_size, 1, kBinTerms);
  const uint32_t count = (kBinTerms + most - 1) / most;
  const uint32_t per_pass = (kBinTerms + count - 1) / count;
  std::vector<AssembleNormalEquationsKernel::TermPass> passes;
  for (uint32_t first = 0; first < kBinTerms; first += per_pass)
    passes.push_back({first, std::min(per_pass, kBinTerms - first)});
  return passes;
}

AssembleNormalEquationsKernel::AssembleNormalEquationsKernel(Context& ctx, uint32_t tf_size, ReductionOptions options)
    : ctx_(ctx),
      tf_size_(tf_size),
      reduction_(Reduction::choose(ctx, "assemble", tf_size, uint64_t(TFM_ASSEMBLE_SLOTS(tf_size)) * gpu::kFixedSlotBytes,
                                   options, kAssemblePrivateMaxBins)),
      passes_(assemble_term_passes(reduction_.mode, tf_size, private_limit(ctx, kPrivateHistogramSlots))),
      range_quads_(texel_range_quads(ctx, options.range_quads, "assemble")) {
  // Pipelines are compiled on first use: a kernel records either variant (pipeline()).
}

const ComputePipeline& AssembleNormalEquationsKernel::pipeline(bool with_before, bool weighted) const {
  SharedPipeline& out = pipelines_[(with_before ? 1 : 0) + (weighted ? 2 : 0)];
  if (!out) out = make_pipeline(with_before, nullptr, weighted);
  return *out;
}

const ComputePipeline& AssembleNormalEquationsKernel::image_pipeline(bool with_before, uint32_t nx, uint32_t ny) const {
  SharedPipeline& out = image_pipelines_[{with_before, nx, ny}];
  const VkExtent3D extent{nx, ny, 1};
  if (!out) out = make_pipeline(with_before, &extent, false);
  return *out;
}

SharedPipeline AssembleNormalEquationsKernel::make_pipeline(bool with_before, const VkExtent3D* image,
                                                          bool weighted) const {
  const char* shader = image      ? "assemble_normal_equations_image"
                       : weighted ? "assemble_normal_equations_weighted"
                                  : "assemble_normal_equations";
  PipelineDesc desc = reduction_.pipeline_desc(
      shader, weighted ? gpu::to_vector(kWeightedBindingCounts) : gpu::to_vector(kAssembleBindingCounts),
      sizeof(gpu::VoxelPairPush));
  desc.binding_kinds = texel_binding_kinds(
      desc.binding_counts.size(),
      {TFM_ASSEMBLE_BINDING_REF_TF, TFM_ASSEMBLE_BINDING_REF_QUADS, TFM_ASSEMBLE_BINDING_OPT_QUADS,
       TFM_ASSEMBLE_BINDING_REF_FIELD, TFM_ASSEMBLE_BINDING_OPT_FIELD});
  if (weighted)
    for (uint32_t b : {TFM_ASSEMBLE_BINDING_WEIGHTS, TFM_ASSEMBLE_BINDING_WEIGHT_QUADS})
      desc.binding_kinds.at(b) = DescriptorKind::UniformTexelBuffer;
  if (image)
    bind_fields_as_images(desc, {TFM_ASSEMBLE_BINDING_REF_FIELD, TFM_ASSEMBLE_BINDING_OPT_FIELD,
                               TFM_ASSEMBLE_BINDING_REF_QUADS, TFM_ASSEMBLE_BINDING_OPT_QUADS});
  desc.specialization = gpu::by_id(
      {{TFM_SPEC_WORKGROUP_X, reduction_.workgroup_size},
       {TFM_ASSEMBLE_SPEC_MODE, reduction_.shader_mode()},
       {TFM_ASSEMBLE_SPEC_SHARED_SLOTS, reduction_.mode == ReductionMode::RunsShared ? slots() : 1u},
       {TFM_ASSEMBLE_SPEC_PRIVATE_BINS, reduction_.mode == ReductionMode::Private ? tf_size_ : 0u},
       {TFM_ASSEMBLE_SPEC_TERM_FIRST, passes_.front().first},
       {TFM_ASSEMBLE_SPEC_TERM_COUNT, passes_.front().count},
       {TFM_ASSEMBLE_SPEC_WITH_BEFORE, with_before ? 1u : 0u},
       {TFM_ASSEMBLE_SPEC_IMAGE_NX, image ? image->width : 1u},
       {TFM_ASSEMBLE_SPEC_IMAGE_NY, image ? image->height : 1u}});
  return shared_pipeline(ctx_, desc);
}

AssembleNormalEquationsKernel::~AssembleNormalEquationsKernel() = default;

uint32_t AssembleNormalEquationsKernel::slots() const { return TFM_ASSEMBLE_SLOTS(tf_size_); }

gpu::VoxelPairPush AssembleNormalEquationsKernel::push_for(const FieldMapping& ref_map, const FieldMapping& opt_map,
                                                           const Buffer& ref_tf, Buffer& accum,
                                                           const FieldMapping* before_map) const {
  if (opt_map.tf_size != tf_size_) throw std::invalid_argument("assemble: mapping TF size differs from kernel's");
  if (accum.size() < slots() * gpu::kFixedSlotBytes)
    throw std::invalid_argument("assemble: accumulator buffer too small");
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16)
    throw std::invalid_argument("assemble: reference TF buffer holds fewer entries than its mapping");
  gpu::VoxelPairPush push = make_voxel_pair_push(ref_map, opt_map);
  if (before_map) {
    if (before_map->tf_size != ref_map.tf_size)
      throw std::invalid_argument("assemble: the before mapping must map onto the reference TF's entries");
    push.before_lo = before_map->lo;
    push.before_scale = before_map->scale;
  }
  return push;
}

void AssembleNormalEquationsKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                                           const FieldMapping& ref_map, const FieldMapping& opt_map,
                                           const Buffer& ref_tf, Buffer& accum, const FieldMapping* before_map,
                                           const DeviceField* weights) const {
  check_voxel_pair(ref, opt, "assemble");
  if (weights) {
    check_voxel_pair(ref, *weights, "assemble (weights)");
    if (weights->format() != FieldFormat::Float32)
      throw std::invalid_argument("assemble: the weights must be a float32 field");
  }
  gpu::VoxelPairPush push = push_for(ref_map, opt_map, ref_tf, accum, before_map);
  const Binding tf = Binding::texels(ref_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(ref_map.tf_size) * 16);
  const ComputePipeline& pipe = pipeline(before_map != nullptr, weights != nullptr);
  const uint32_t rows = static_cast<uint32_t>(passes_.size());
  for (const QuadRange& r : quad_ranges(ref, range_quads_)) {  // one dispatch per range, a row per pass
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    std::vector<Binding> bindings{voxel_texels(ref, r.chunk), voxel_texels(opt, r.chunk), tf, accum,
                                  quad_texels(ref, r), quad_texels(opt, r)};
    if (weights) {
      bindings.push_back(voxel_texels(*weights, r.chunk));
      bindings.push_back(quad_texels(*weights, r));
    }
    batch.dispatch(pipe, bindings, push, {reduction_.groups(ctx_, r.voxels), rows});
    // Successive dispatches add into the same accumulators.
    batch.barrier();
  }
}

void AssembleNormalEquationsKernel::record(CommandBatch& batch, const ImageFieldView& ref, const ImageFieldView& opt,
                                           const FieldMapping& ref_map, const FieldMapping& opt_map,
                                           const Buffer& ref_tf, Buffer& accum, const FieldMapping* before_map) const {
  const uint64_t voxels = check_image_pair(ref, opt, "assemble");
  const VkExtent3D& e = ref.extent;
  gpu::VoxelPairPush push = push_for(ref_map, opt_map, ref_tf, accum, before_map);
  const Binding tf = Binding::texels(ref_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(ref_map.tf_size) * 16);
  const Binding r_image = Binding::image(ref.view, ref.layout), o_image = Binding::image(opt.view, opt.layout);
  const ComputePipeline& pipe = image_pipeline(before_map != nullptr, e.width, e.height);
  const uint32_t rows = static_cast<uint32_t>(passes_.size());
  for (const QuadRange& r : quad_ranges(std::span<const uint64_t>(&voxels, 1), range_quads_)) {
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    batch.dispatch(pipe, {r_image, o_image, tf, accum, r_image, o_image}, push,
                   {reduction_.groups(ctx_, r.voxels), rows});
    batch.barrier();
  }
}

}  // namespace tfm
