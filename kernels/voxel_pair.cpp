// Pipelines and dispatch recording of the voxel-pair kernels.
#include "voxel_pair.h"

#include "shader_registry.h"

#include <algorithm>
#include <stdexcept>

#include "context.h"

namespace tfm {

static_assert(sizeof(gpu::VoxelPairPush) == 40, "VoxelPairPush must match the GLSL std430 block");

namespace {
// Bindings in the order record() lists each kernel's buffers.
constexpr auto kAssembleBindingCounts =
    gpu::binding_counts({TFM_ASSEMBLE_BINDING_REF_FIELD, TFM_ASSEMBLE_BINDING_OPT_FIELD, TFM_ASSEMBLE_BINDING_REF_TF,
                         TFM_ASSEMBLE_BINDING_ACCUM, TFM_ASSEMBLE_BINDING_REF_QUADS, TFM_ASSEMBLE_BINDING_OPT_QUADS});
constexpr auto kLossBindingCounts =
    gpu::binding_counts({TFM_LOSS_BINDING_REF_FIELD, TFM_LOSS_BINDING_OPT_FIELD, TFM_LOSS_BINDING_REF_TF,
                         TFM_LOSS_BINDING_OPT_TF, TFM_LOSS_BINDING_ACCUM, TFM_LOSS_BINDING_REF_QUADS,
                         TFM_LOSS_BINDING_OPT_QUADS});
}  // namespace

gpu::VoxelPairPush make_voxel_pair_push(const FieldMapping& ref, const FieldMapping& opt) {
  gpu::VoxelPairPush p{};
  p.opt_tf_size = opt.tf_size;
  p.ref_tf_size = ref.tf_size;
  p.ref_lo = ref.lo;
  p.ref_scale = ref.scale;
  p.opt_lo = opt.lo;
  p.opt_scale = opt.scale;
  return p;
}

uint32_t voxel_groups(const Context& ctx, uint64_t voxels) {
  // Enough voxels per group to amortize its flush of the shared accumulators.
  const uint64_t per_group = uint64_t(TFM_VOXEL_WORKGROUP) * 64;
  uint64_t groups = (voxels + per_group - 1) / per_group;
  return static_cast<uint32_t>(std::clamp<uint64_t>(groups, 1, ctx.limits().maxComputeWorkGroupCount[0]));
}

uint32_t lane_workgroup_size(const Context& ctx, uint32_t requested, const char* kernel) {
  const uint32_t limit = ctx.limits().maxComputeWorkGroupSize[0], subgroup = std::max(1u, ctx.subgroup_size());
  const uint32_t size = requested ? requested : is_cpu_device(ctx) ? std::min(subgroup, limit) : TFM_VOXEL_WORKGROUP;
  if (size == 0 || size > limit || size % subgroup != 0)
    throw std::invalid_argument(std::string(kernel) + ": workgroup size " + std::to_string(size) +
                                " is not a multiple of the subgroup size " + std::to_string(subgroup) +
                                " within the device's " + std::to_string(limit));
  return size;
}

uint32_t lane_groups(const Context& ctx, uint32_t workgroup_size, uint64_t voxels, uint64_t lane_voxels,
                     uint64_t min_lane_voxels) {
  if (workgroup_size == TFM_VOXEL_WORKGROUP) return voxel_groups(ctx, voxels);
  const uint64_t long_lanes = voxels / (uint64_t(workgroup_size) * std::max<uint64_t>(1, lane_voxels));
  const uint64_t spread =
      std::min<uint64_t>(kPrivateMinGroups, voxels / (uint64_t(workgroup_size) * std::max<uint64_t>(1, min_lane_voxels)));
  return static_cast<uint32_t>(
      std::clamp<uint64_t>(std::max(long_lanes, spread), 1, ctx.limits().maxComputeWorkGroupCount[0]));
}

uint64_t texel_range_quads(const Context& ctx, uint64_t requested, const char* kernel) {
  if (requested % 64) throw std::invalid_argument(std::string(kernel) + ": range_quads must be a multiple of 64");
  return requested ? requested : std::max<uint64_t>(64, ctx.limits().maxTexelBufferElements / 64 * 64);
}

uint64_t voxel_texel_range_quads(const Context& ctx, uint64_t requested, const char* kernel) {
  const uint64_t texels = ctx.limits().maxTexelBufferElements;
  const uint64_t limit = std::max<uint64_t>(64, (texels - std::min<uint64_t>(texels, 64)) / 4 / 64 * 64);
  const uint64_t quads = requested ? texel_range_quads(ctx, requested, kernel) : limit;
  if (quads > limit)
    throw std::invalid_argument(std::string(kernel) + ": ranges of " + std::to_string(quads) + " quads exceed the device's " +
                                std::to_string(texels) + " texels");
  return quads;
}

std::vector<QuadRange> quad_ranges(const DeviceField& field, uint64_t range_quads) {
  std::vector<uint64_t> sizes(field.chunk_count());
  for (size_t c = 0; c < sizes.size(); ++c) sizes[c] = field.chunk_size(c);
  return quad_ranges(sizes, range_quads, field.format());
}

std::vector<QuadRange> quad_ranges(std::span<const uint64_t> chunk_voxels, uint64_t range_quads, FieldFormat format) {
  const uint64_t voxel_bytes = field_format_bytes(format);
  std::vector<QuadRange> out;
  for (size_t c = 0; c < chunk_voxels.size(); ++c) {
    const uint64_t chunk = chunk_voxels[c];
    for (uint64_t first = 0; first < chunk; first += 4 * range_quads) {
      QuadRange r;
      r.chunk = c;
      r.first = first;
      r.voxels = std::min(4 * range_quads, chunk - first);
      r.format = r.voxels >= 4 ? quad_texel_format(format) : voxel_texel_format(format);
      r.bytes = r.voxels >= 4 ? r.voxels / 4 * 4 * voxel_bytes : voxel_bytes;
      out.push_back(r);
    }
  }
  return out;
}

Binding quad_texels(const DeviceField& field, const QuadRange& r) {
  const uint64_t voxel_bytes = field_format_bytes(field.format());
  const bool quads = r.voxels >= 4;
  return Binding::texels(field.chunk(r.chunk),
                         quads ? quad_texel_format(field.format()) : voxel_texel_format(field.format()),
                         r.first * voxel_bytes, quads ? r.voxels / 4 * 4 * voxel_bytes : voxel_bytes);
}

Binding voxel_texels(const DeviceField& field, size_t c) {
  return Binding::texels(field.chunk(c), voxel_texel_format(field.format()), 0,
                         field.chunk_size(c) * field_format_bytes(field.format()));
}

std::vector<double> decode_fixed_point(const std::vector<uint32_t>& words) {
  // Unsigned slots of shaders/fixed_point.glsl (signed ones: FixedPointTotals).
  std::vector<double> out(words.size() / TFM_FIXED_SLOT_WORDS);
  for (size_t k = 0; k < out.size(); ++k)
    out[k] = (double(words[2 * k + 1]) * TFM_FIXED_ONE + double(words[2 * k])) / TFM_FIXED_ONE;
  return out;
}

static void check_pair(const DeviceField& ref, const DeviceField& opt) {
  if (ref.voxel_count() != opt.voxel_count() || ref.chunk_voxels() != opt.chunk_voxels())
    throw std::invalid_argument("voxel-pair kernel: fields differ in size or chunking");
}

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
  check_pair(ref, opt);
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

VoxelLossKernel::VoxelLossKernel(Context& ctx, uint64_t range_quads, uint32_t workgroup_size)
    : ctx_(ctx),
      range_quads_(texel_range_quads(ctx, range_quads, "voxel_loss")),
      workgroup_size_(lane_workgroup_size(ctx, workgroup_size, "voxel_loss")) {}

VoxelLossKernel::~VoxelLossKernel() = default;

const ComputePipeline& VoxelLossKernel::pipeline(bool with_before) const {
  std::unique_ptr<ComputePipeline>& p = pipelines_[with_before ? 1 : 0];
  if (p) return *p;
  PipelineDesc desc;
  desc.shader = "voxel_loss";
  desc.binding_counts = gpu::to_vector(kLossBindingCounts);
  desc.binding_kinds = texel_binding_kinds(desc.binding_counts.size(),
                                           {TFM_LOSS_BINDING_REF_TF, TFM_LOSS_BINDING_OPT_TF, TFM_LOSS_BINDING_REF_QUADS,
                                            TFM_LOSS_BINDING_OPT_QUADS, TFM_LOSS_BINDING_REF_FIELD,
                                            TFM_LOSS_BINDING_OPT_FIELD});
  desc.push_constant_bytes = sizeof(gpu::VoxelPairPush);
  desc.workgroup_size = workgroup_size_;
  desc.specialization =
      gpu::by_id({{TFM_SPEC_WORKGROUP_X, workgroup_size_}, {TFM_LOSS_SPEC_WITH_BEFORE, with_before ? 1u : 0u}});
  desc.spirv = shader_spirv(desc.shader);
  p = std::make_unique<ComputePipeline>(ctx_, desc);
  return *p;
}

void VoxelLossKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                             const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                             const Buffer& opt_tf, Buffer& accum, const FieldMapping* before_map) const {
  check_pair(ref, opt);
  if (accum.size() < (before_map ? 2 : 1) * TFM_LOSS_SLOTS * gpu::kFixedSlotBytes)
    throw std::invalid_argument("voxel loss: accumulator too small");
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * 16 || opt_tf.size() < uint64_t(opt_map.tf_size) * 16)
    throw std::invalid_argument("voxel loss: a TF buffer holds fewer entries than its mapping");
  const Binding rtf = Binding::texels(ref_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(ref_map.tf_size) * 16);
  const Binding otf = Binding::texels(opt_tf, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(opt_map.tf_size) * 16);
  gpu::VoxelPairPush push = make_voxel_pair_push(ref_map, opt_map);
  if (before_map) {
    if (before_map->tf_size != ref_map.tf_size)
      throw std::invalid_argument("voxel loss: the before mapping must map onto the reference TF's entries");
    push.before_lo = before_map->lo;
    push.before_scale = before_map->scale;
  }
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

}  // namespace tfm
