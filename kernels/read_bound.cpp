// Pipeline and dispatches of the assembly's read bound.
#include "tfmatch/kernels/read_bound.h"

#include <algorithm>
#include <bit>
#include <stdexcept>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/shaders/read_bound_layout.h"
#include "tfmatch/shaders/shader_registry.h"

namespace tfm {

static_assert(sizeof(gpu::ReadBoundPush) == 8, "ReadBoundPush must match the GLSL std430 block");

namespace {
constexpr auto kBindingCounts =
    gpu::binding_counts({TFM_READ_BINDING_REF_FIELD, TFM_READ_BINDING_OPT_FIELD, TFM_READ_BINDING_REF_QUADS,
                         TFM_READ_BINDING_OPT_QUADS, TFM_READ_BINDING_RESULT});
}  // namespace

std::array<uint32_t, 2> field_pair_bit_sums(std::span<const float> ref, std::span<const float> opt) {
  std::array<uint32_t, 2> s{0, 0};
  for (float v : ref) s[0] += std::bit_cast<uint32_t>(v);
  for (float v : opt) s[1] += std::bit_cast<uint32_t>(v);
  return s;
}

FieldPairReadKernel::FieldPairReadKernel(Context& ctx, uint64_t range_quads, uint64_t lane_voxels)
    : ctx_(ctx),
      range_quads_(texel_range_quads(ctx, range_quads, "field_pair_read")),
      lane_voxels_(lane_voxels),
      workgroup_size_(lane_voxels ? TFM_VOXEL_WORKGROUP : lane_workgroup_size(ctx, 0, "field_pair_read")) {
  PipelineDesc desc;
  desc.shader = "field_pair_read";
  desc.binding_counts = gpu::to_vector(kBindingCounts);
  desc.binding_kinds =
      texel_binding_kinds(desc.binding_counts.size(), {TFM_READ_BINDING_REF_QUADS, TFM_READ_BINDING_OPT_QUADS});
  desc.push_constant_bytes = sizeof(gpu::ReadBoundPush);
  desc.workgroup_size = workgroup_size_;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, workgroup_size_}});
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = shared_pipeline(ctx, desc);
}

FieldPairReadKernel::~FieldPairReadKernel() = default;

void FieldPairReadKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                                 Buffer& result) const {
  if (ref.voxel_count() != opt.voxel_count() || ref.chunk_voxels() != opt.chunk_voxels())
    throw std::invalid_argument("field_pair_read: fields differ in size or chunking");
  if (result.size() < 2 * sizeof(uint32_t)) throw std::invalid_argument("field_pair_read: result buffer too small");
  if (ref.format() != FieldFormat::Float32 || opt.format() != FieldFormat::Float32)
    throw std::invalid_argument("field_pair_read: float32 fields only (the read bound of tfmatch's own uploads)");
  for (const QuadRange& r : quad_ranges(ref, range_quads_)) {  // the assembly's dispatches
    const gpu::ReadBoundPush push{static_cast<uint32_t>(r.voxels), static_cast<uint32_t>(r.first)};
    batch.dispatch(*pipeline_,
                   {ref.chunk(r.chunk), opt.chunk(r.chunk),
                    Binding::texels(ref.chunk(r.chunk), r.format, r.first * 4, r.bytes),
                    Binding::texels(opt.chunk(r.chunk), r.format, r.first * 4, r.bytes), result},
                   push,
                   {lane_voxels_ ? voxel_groups(ctx_, r.voxels, lane_voxels_)
                                 : lane_groups(ctx_, workgroup_size_, r.voxels)});
    batch.barrier();
  }
}

std::array<uint32_t, 2> FieldPairReadKernel::run(const DeviceField& ref, const DeviceField& opt, double* gpu_ms) const {
  Buffer result(ctx_, 2 * sizeof(uint32_t), MemoryUsage::Device, "read bound sums");
  CommandBatch batch(ctx_);
  batch.fill(result, 0u);
  batch.barrier();
  const bool timed = gpu_ms && ctx_.timestamps_supported();
  const uint32_t t0 = timed ? batch.timestamp() : 0;
  record(batch, ref, opt, result);
  const uint32_t t1 = timed ? batch.timestamp() : 0;
  batch.submit_and_wait();
  if (gpu_ms) *gpu_ms = timed ? batch.elapsed_ms(t0, t1) : -1.0;
  std::array<uint32_t, 2> sums{};
  readback(ctx_, result, sums.data(), sizeof(sums));
  return sums;
}

}  // namespace tfm
