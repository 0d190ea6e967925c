// Voxel vectors and the prepare / gather / scatter kernels of the matrix-free solvers.
#include "tfmatch/kernels/sparse_ops.h"

#include "tfmatch/shaders/shader_registry.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/kernels/diffdvr.h"  // FixedPointTotals, the decoder of signed accumulators
#include "tfmatch/kernels/voxel_pair.h"

namespace tfm {

static_assert(sizeof(gpu::PreparePush) == 44, "PreparePush must match the GLSL std430 block");
static_assert(sizeof(gpu::SparsePush) == 12, "SparsePush must match the GLSL std430 block");
static_assert(sizeof(gpu::CglsState) == 112, "CglsState must match the GLSL std430 struct");

namespace {
constexpr uint64_t kRgbaBytes = 4 * sizeof(float);

// Bindings in the order record() lists each kernel's buffers.
constexpr auto kPrepareBindingCounts =
    gpu::binding_counts({TFM_PREPARE_BINDING_REF_FIELD, TFM_PREPARE_BINDING_OPT_FIELD, TFM_PREPARE_BINDING_REF_TF,
                         TFM_PREPARE_BINDING_COORD, TFM_PREPARE_BINDING_RGBA, TFM_PREPARE_BINDING_COORD_QUADS});
constexpr auto kGatherBindingCounts =
    gpu::binding_counts({TFM_GATHER_BINDING_COORD, TFM_GATHER_BINDING_X, TFM_GATHER_BINDING_OUT,
                         TFM_GATHER_BINDING_NORM, TFM_GATHER_BINDING_STATE, TFM_GATHER_BINDING_COORD_QUADS});
constexpr auto kScatterBindingCounts =
    gpu::binding_counts({TFM_SCATTER_BINDING_COORD, TFM_SCATTER_BINDING_RESIDUAL, TFM_SCATTER_BINDING_P,
                         TFM_SCATTER_BINDING_STATE, TFM_SCATTER_BINDING_ACCUM, TFM_SCATTER_BINDING_COORD_QUADS,
                         TFM_SCATTER_BINDING_RESIDUAL_TEXELS});

// The TFM_WEIGHTED variants: the same bindings, then the weights and row scales.
constexpr auto kWeightedPrepareBindingCounts =
    gpu::binding_counts({TFM_PREPARE_BINDING_REF_FIELD, TFM_PREPARE_BINDING_OPT_FIELD, TFM_PREPARE_BINDING_REF_TF,
                         TFM_PREPARE_BINDING_COORD, TFM_PREPARE_BINDING_RGBA, TFM_PREPARE_BINDING_COORD_QUADS,
                         TFM_PREPARE_BINDING_WEIGHTS, TFM_PREPARE_BINDING_SCALE});
constexpr auto kWeightedGatherBindingCounts =
    gpu::binding_counts({TFM_GATHER_BINDING_COORD, TFM_GATHER_BINDING_X, TFM_GATHER_BINDING_OUT,
                         TFM_GATHER_BINDING_NORM, TFM_GATHER_BINDING_STATE, TFM_GATHER_BINDING_COORD_QUADS,
                         TFM_GATHER_BINDING_SCALE});
constexpr auto kWeightedScatterBindingCounts =
    gpu::binding_counts({TFM_SCATTER_BINDING_COORD, TFM_SCATTER_BINDING_RESIDUAL, TFM_SCATTER_BINDING_P,
                         TFM_SCATTER_BINDING_STATE, TFM_SCATTER_BINDING_ACCUM, TFM_SCATTER_BINDING_COORD_QUADS,
                         TFM_SCATTER_BINDING_RESIDUAL_TEXELS, TFM_SCATTER_BINDING_SCALE});

// A TF-sized vector (N RGBA entries) as texels.
Binding tf_texels(const Buffer& b, uint32_t n) {
  return Binding::texels(b, VK_FORMAT_R32G32B32A32_SFLOAT, 0, uint64_t(n) * kRgbaBytes);
}
}  // namespace

WeightedPipelines::WeightedPipelines(Context& ctx, PipelineDesc plain, std::vector<uint32_t> weighted_counts,
                                     std::initializer_list<uint32_t> weighted_texels)
    : ctx_(ctx), weighted_desc_(plain) {
  plain.spirv = shader_spirv(plain.shader);
  plain_ = shared_pipeline(ctx, plain);
  // "sparse_scatter_int64" -> "sparse_scatter_weighted_int64"
  const size_t int64 = weighted_desc_.shader.find("_int64");
  weighted_desc_.shader.insert(int64 == std::string::npos ? weighted_desc_.shader.size() : int64, "_weighted");
  weighted_desc_.binding_counts = std::move(weighted_counts);
  weighted_desc_.binding_kinds.resize(weighted_desc_.binding_counts.size(), DescriptorKind::StorageBuffer);
  for (uint32_t b : weighted_texels) weighted_desc_.binding_kinds.at(b) = DescriptorKind::UniformTexelBuffer;
}

const ComputePipeline& WeightedPipelines::get(bool weighted) const {
  if (!weighted) return *plain_;
  if (!weighted_) {
    PipelineDesc desc = weighted_desc_;
    desc.spirv = shader_spirv(desc.shader);
    weighted_ = shared_pipeline(ctx_, desc);
  }
  return *weighted_;
}

VoxelVectors::VoxelVectors(Context& ctx, const DeviceField& ref, const DeviceField& opt, uint64_t max_chunk_voxels,
                           bool weighted)
    : voxels_(ref.voxel_count()), field_chunk_voxels_(ref.chunk_voxels()) {
  if (ref.voxel_count() != opt.voxel_count() || ref.chunk_voxels() != opt.chunk_voxels())
    throw std::invalid_argument("voxel vectors: fields differ in size or chunking");
  uint64_t limit = ctx.max_buffer_bytes() / kRgbaBytes;
  if (max_chunk_voxels) limit = std::min(limit, max_chunk_voxels);
  if (ref.chunk_count() == 1) {
    chunk_voxels_ = std::min(voxels_, limit);
  } else {
    // Several field chunks: the chunk size must divide the field chunk so that no chunk straddles
    // two field buffers. Field chunks are multiples of 1024 voxels, so a divisor is found quickly.
    const uint64_t f = field_chunk_voxels_;
    for (uint64_t k = (f + limit - 1) / limit; k <= f; ++k) {
      if (f % k == 0) {
        chunk_voxels_ = f / k;
        break;
      }
    }
  }
  if (chunk_voxels_ == 0)
    throw std::runtime_error("voxel vectors: no chunk size fits " + std::to_string(voxels_) +
                             " voxels in storage buffers of " + std::to_string(ctx.max_buffer_bytes()) + " bytes");
  const size_t count = size_t((voxels_ + chunk_voxels_ - 1) / chunk_voxels_);
  // A coordinate and an RGBA row per voxel (and a scale when weighted): the largest buffers of a
  // CGLS solve, checked as the fields were (cgls at 150 MiB of budget took 548 MiB unchecked).
  check_device_memory(ctx, voxels_ * (sizeof(float) + kRgbaBytes + (weighted ? sizeof(float) : 0)),
                      "CGLS: per-voxel vectors of " + std::to_string(voxels_) + " voxels");
  coord_.reserve(count);
  rgba_.reserve(count);
  for (size_t c = 0; c < count; ++c) {
    coord_.emplace_back(ctx, chunk_size(c) * sizeof(float), MemoryUsage::Device,
                        "voxel coordinates chunk " + std::to_string(c));
    rgba_.emplace_back(ctx, chunk_size(c) * kRgbaBytes, MemoryUsage::Device, "voxel RGBA chunk " + std::to_string(c));
    if (weighted)
      scale_.emplace_back(ctx, chunk_size(c) * sizeof(float), MemoryUsage::Device,
                          "voxel row scales chunk " + std::to_string(c));
  }
}

const Buffer& VoxelVectors::scale(size_t c) const {
  if (!weighted()) throw std::logic_error("voxel vectors: unweighted vectors have no row scales");
  return scale_[c];
}

uint64_t VoxelVectors::chunk_size(size_t c) const { return std::min(chunk_voxels_, voxels_ - chunk_begin(c)); }

std::vector<uint64_t> VoxelVectors::chunk_sizes() const {
  std::vector<uint64_t> sizes(chunk_count());
  for (size_t c = 0; c < sizes.size(); ++c) sizes[c] = chunk_size(c);
  return sizes;
}

std::vector<float> VoxelVectors::read_coords(Context& ctx) const {
  std::vector<float> out(voxels_);
  for (size_t c = 0; c < chunk_count(); ++c)
    readback(ctx, coord_[c], out.data() + chunk_begin(c), chunk_size(c) * sizeof(float));
  return out;
}

std::vector<float> VoxelVectors::read_rgba(Context& ctx) const {
  std::vector<float> out(voxels_ * 4);
  for (size_t c = 0; c < chunk_count(); ++c)
    readback(ctx, rgba_[c], out.data() + 4 * chunk_begin(c), chunk_size(c) * kRgbaBytes);
  return out;
}

SparsePrepareKernel::SparsePrepareKernel(Context& ctx, uint64_t range_quads, uint32_t workgroup_size)
    : ctx_(ctx),
      range_quads_(voxel_texel_range_quads(ctx, range_quads, "sparse_prepare")),
      workgroup_size_(lane_workgroup_size(ctx, workgroup_size, "sparse_prepare")) {
  PipelineDesc desc;
  desc.shader = "sparse_prepare";
  desc.binding_counts = gpu::to_vector(kPrepareBindingCounts);
  desc.binding_kinds = texel_binding_kinds(desc.binding_counts.size(), {TFM_PREPARE_BINDING_REF_FIELD,
                                                                      TFM_PREPARE_BINDING_OPT_FIELD, TFM_PREPARE_BINDING_REF_TF});
  desc.push_constant_bytes = sizeof(gpu::PreparePush);
  desc.workgroup_size = workgroup_size_;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, workgroup_size_}});
  pipelines_ = std::make_unique<WeightedPipelines>(ctx, desc, gpu::to_vector(kWeightedPrepareBindingCounts),
                                                   std::initializer_list<uint32_t>{TFM_PREPARE_BINDING_WEIGHTS});
}

void SparsePrepareKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                                 const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                                 VoxelVectors& v, const DeviceField* weights) const {
  if (ref.voxel_count() != v.voxel_count() || opt.voxel_count() != v.voxel_count())
    throw std::invalid_argument("sparse_prepare: fields and voxel vectors differ in size");
  if ((weights != nullptr) != v.weighted())
    throw std::invalid_argument("sparse_prepare: weights go with weighted voxel vectors, and only with them");
  if (weights && (weights->voxel_count() != ref.voxel_count() || weights->chunk_voxels() != ref.chunk_voxels() ||
                  weights->format() != FieldFormat::Float32))
    throw std::invalid_argument("sparse_prepare: the weights must be a float32 field chunked as the fields");
  if (ref_tf.size() < uint64_t(ref_map.tf_size) * kRgbaBytes)
    throw std::invalid_argument("sparse_prepare: TF buffer smaller than its mapping's size");
  gpu::PreparePush push{};
  push.opt_tf_size = opt_map.tf_size;
  push.ref_tf_size = ref_map.tf_size;
  push.ref_lo = ref_map.lo;
  push.ref_scale = ref_map.scale;
  push.opt_lo = opt_map.lo;
  push.opt_scale = opt_map.scale;
  const Binding tf = tf_texels(ref_tf, ref_map.tf_size);
  const uint64_t align = ctx_.limits().minTexelBufferOffsetAlignment;
  for (const QuadRange& r : quad_ranges(v.chunk_sizes(), range_quads_)) {
    // The fields' views start at the alignment at or below the range's first voxel.
    const uint64_t first = v.field_offset(r.chunk) + r.first;
    const size_t f = v.field_chunk(r.chunk);
    // Each field's view in its own format, from the alignment at or below the range's first voxel.
    auto view_of = [&](const DeviceField& field, uint32_t& shift) {
      const uint64_t voxel_bytes = field_format_bytes(field.format());
      const uint64_t offset = first * voxel_bytes / align * align;
      shift = static_cast<uint32_t>(first - offset / voxel_bytes);
      return Binding::texels(field.chunk(f), voxel_texel_format(field.format()), offset,
                             (shift + r.voxels) * voxel_bytes);
    };
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    const Binding ref_view = view_of(ref, push.field_shift), opt_view = view_of(opt, push.opt_field_shift);
    std::vector<Binding> bindings{ref_view, opt_view, tf, v.coord(r.chunk), v.rgba(r.chunk), v.coord(r.chunk)};
    if (weights) {
      bindings.push_back(view_of(*weights, push.weight_field_shift));
      bindings.push_back(v.scale(r.chunk));
    }
    batch.dispatch(pipelines_->get(weights != nullptr), bindings, push, {lane_groups(ctx_, workgroup_size_, r.voxels)});
  }
}

SparseGatherKernel::SparseGatherKernel(Context& ctx, bool write_out, bool accumulate_norm, bool scaled,
                                       uint64_t range_quads, uint32_t workgroup_size)
    : ctx_(ctx),
      scaled_(scaled),
      range_quads_(texel_range_quads(ctx, range_quads, "sparse_gather")),
      workgroup_size_(lane_workgroup_size(ctx, workgroup_size, "sparse_gather")),
      dummy_state_(ctx, sizeof(gpu::CglsState), MemoryUsage::Device, "gather unused state") {
  PipelineDesc desc;
  desc.shader = "sparse_gather";
  desc.binding_counts = gpu::to_vector(kGatherBindingCounts);
  desc.binding_kinds =
      texel_binding_kinds(desc.binding_counts.size(), {TFM_GATHER_BINDING_X, TFM_GATHER_BINDING_COORD_QUADS});
  desc.push_constant_bytes = sizeof(gpu::SparsePush);
  desc.workgroup_size = workgroup_size_;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, workgroup_size_},
                                    {TFM_GATHER_SPEC_WRITE_OUT, write_out ? 1u : 0u},
                                    {TFM_GATHER_SPEC_ACCUMULATE_NORM, accumulate_norm ? 1u : 0u},
                                    {TFM_GATHER_SPEC_NORM_SCALED, scaled ? 1u : 0u}});
  pipelines_ = std::make_unique<WeightedPipelines>(ctx, desc, gpu::to_vector(kWeightedGatherBindingCounts));
}

void SparseGatherKernel::record(CommandBatch& batch, VoxelVectors& v, uint32_t tf_size, const Buffer& x,
                                Buffer& norm_accum, const Buffer* state) const {
  if (tf_size < 2 || x.size() < uint64_t(tf_size) * kRgbaBytes)
    throw std::invalid_argument("sparse_gather: TF buffer smaller than N RGBA entries");
  if (norm_accum.size() < TFM_GATHER_NORM_SLOTS * gpu::kFixedSlotBytes)
    throw std::invalid_argument("sparse_gather: norm accumulator too small");
  if (scaled_ && (!state || state->size() < sizeof(gpu::CglsState)))
    throw std::invalid_argument("sparse_gather: the scaled norm needs the CGLS state");
  const Buffer& st = scaled_ ? *state : dummy_state_;
  const Binding xt = tf_texels(x, tf_size);
  gpu::SparsePush push{0, tf_size, 0};
  for (const QuadRange& r : quad_ranges(v.chunk_sizes(), range_quads_)) {
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    std::vector<Binding> bindings{v.coord(r.chunk), xt, v.rgba(r.chunk), norm_accum, st,
                                  Binding::texels(v.coord(r.chunk), r.format, r.first * 4, r.bytes)};
    if (v.weighted()) bindings.push_back(v.scale(r.chunk));
    batch.dispatch(pipelines_->get(v.weighted()), bindings, push, {lane_groups(ctx_, workgroup_size_, r.voxels)});
    // Successive ranges add into the same accumulators.
    batch.barrier();
  }
}

uint64_t signed_accumulator_bytes(uint32_t tf_size) {
  return TFM_TF_GRADIENT_SLOTS(uint64_t(tf_size)) * gpu::kFixedSlotBytes;
}

bool signed_slots_fit_shared(const Context& ctx, uint32_t tf_size) {
  return signed_accumulator_bytes(tf_size) <= ctx.limits().maxComputeSharedMemorySize;
}

std::vector<double> decode_signed_fixed_point(const std::vector<uint32_t>& words) {
  FixedPointTotals totals(words.size() / TFM_FIXED_SLOT_WORDS);
  totals.add(words.data());
  return totals.values();
}

SparseScatterKernel::SparseScatterKernel(Context& ctx, uint32_t tf_size, bool update_residual, ReductionOptions options,
                                         uint64_t range_quads)
    : ctx_(ctx),
      tf_size_(tf_size),
      update_(update_residual),
      range_quads_(voxel_texel_range_quads(ctx, range_quads, "sparse_scatter")),  // r: a texel per voxel
      reduction_(Reduction::choose(ctx, "sparse_scatter", tf_size, signed_accumulator_bytes(tf_size), options)),
      dummy_p_(ctx, uint64_t(tf_size) * kRgbaBytes, MemoryUsage::Device, "scatter unused p"),
      dummy_state_(ctx, sizeof(gpu::CglsState), MemoryUsage::Device, "scatter unused state") {
  PipelineDesc desc =
      reduction_.pipeline_desc("sparse_scatter", gpu::to_vector(kScatterBindingCounts), sizeof(gpu::SparsePush));
  desc.binding_kinds = texel_binding_kinds(desc.binding_counts.size(), {TFM_SCATTER_BINDING_P, TFM_SCATTER_BINDING_COORD_QUADS,
                                                                      TFM_SCATTER_BINDING_RESIDUAL_TEXELS});
  const bool shared = reduction_.mode == ReductionMode::RunsShared;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, reduction_.workgroup_size},
                                    {TFM_SCATTER_SPEC_MODE, reduction_.shader_mode()},
                                    {TFM_SCATTER_SPEC_SHARED_SLOTS, shared ? TFM_TF_GRADIENT_SLOTS(tf_size) : 1u},
                                    {TFM_SCATTER_SPEC_PRIVATE_BINS, reduction_.mode == ReductionMode::Private ? tf_size : 0u},
                                    {TFM_SCATTER_SPEC_UPDATE_RESIDUAL, update_residual ? 1u : 0u}});
  pipelines_ = std::make_unique<WeightedPipelines>(ctx, desc, gpu::to_vector(kWeightedScatterBindingCounts));
}

void SparseScatterKernel::record(CommandBatch& batch, VoxelVectors& v, Buffer& accum) const {
  if (update_) throw std::logic_error("sparse_scatter: this pipeline updates the residual; use record_update");
  record_ranges(batch, v, dummy_p_, dummy_state_, accum);
}

void SparseScatterKernel::record_update(CommandBatch& batch, VoxelVectors& v, const Buffer& p, const Buffer& state,
                                        Buffer& accum) const {
  if (!update_) throw std::logic_error("sparse_scatter: this pipeline does not update the residual");
  if (p.size() < uint64_t(tf_size_) * kRgbaBytes || state.size() < sizeof(gpu::CglsState))
    throw std::invalid_argument("sparse_scatter: p or state buffer too small");
  record_ranges(batch, v, p, state, accum);
}

void SparseScatterKernel::record_ranges(CommandBatch& batch, VoxelVectors& v, const Buffer& p, const Buffer& state,
                                        Buffer& accum) const {
  if (accum.size() < signed_accumulator_bytes(tf_size_))
    throw std::invalid_argument("sparse_scatter: accumulator buffer too small");
  const Binding pt = tf_texels(p, tf_size_);
  gpu::SparsePush push{0, tf_size_, 0};
  for (const QuadRange& r : quad_ranges(v.chunk_sizes(), range_quads_)) {
    push.voxel_count = static_cast<uint32_t>(r.voxels);
    push.first_voxel = static_cast<uint32_t>(r.first);
    std::vector<Binding> bindings{v.coord(r.chunk), v.rgba(r.chunk), pt, state, accum,
                                  Binding::texels(v.coord(r.chunk), r.format, r.first * 4, r.bytes),
                                  Binding::texels(v.rgba(r.chunk), VK_FORMAT_R32G32B32A32_SFLOAT,
                                                  r.first * kRgbaBytes, r.voxels * kRgbaBytes)};
    if (v.weighted()) bindings.push_back(v.scale(r.chunk));
    batch.dispatch(pipelines_->get(v.weighted()), bindings, push, {reduction_.groups(ctx_, r.voxels)});
    // Successive ranges add into the same accumulators.
    batch.barrier();
  }
}

}  // namespace tfm
