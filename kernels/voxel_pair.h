// The two voxel-pair kernels (normal-equation assembly and voxel loss): small wrappers that
// create the pipeline and record one dispatch per field chunk.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>
#include <memory>

#include "buffer.h"
#include "commands.h"
#include "device_field.h"
#include "pipeline.h"
#include "reduction.h"
#include "shared_layout.h"

namespace tfm {

class Context;

gpu::VoxelPairPush make_voxel_pair_push(const FieldMapping& ref, const FieldMapping& opt);

// Adds M, S^T b, b^T b and the voxel count of (ref, opt) to a 32.32 fixed-point accumulator
// buffer of TFM_ASSEMBLE_SLOTS(N) slots (8 bytes each, low word first). The result is
// bit-identical for every mode, atomic width, chunking and workgroup count. Throws
// std::invalid_argument for fewer than 2 entries, std::runtime_error when a forced mode or
// width is not available on the device (shared memory too small, no 64-bit atomics).
class AssembleNormalEquationsKernel {
 public:
  AssembleNormalEquationsKernel(Context& ctx, uint32_t tf_size, ReductionOptions options = {});
  ~AssembleNormalEquationsKernel();
  uint32_t tf_size() const { return tf_size_; }
  uint32_t slots() const;
  ReductionMode mode() const { return reduction_.mode; }
  bool int64_atomics() const { return reduction_.int64; }
  // Records one dispatch per chunk, texel range and term pass (barriers between them). With
  // `before_map` (the second field mapped onto the reference TF's entries: tf_size of ref_map)
  // the kernel also adds the loss before optimization to slots [6N+4, 6N+8) (shared_layout.h).
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, Buffer& accum,
              const FieldMapping* before_map = nullptr) const;

  // Which of the 11 bin terms one pass adds (shaders/assemble_normal_equations.comp).
  struct TermPass {
    uint32_t first = 0, count = 11;
  };
  const std::vector<TermPass>& passes() const { return passes_; }

 private:
  Context& ctx_;
  uint32_t tf_size_;
  Reduction reduction_;
  std::vector<TermPass> passes_;
  uint64_t range_quads_;
  // One per pass, without and with the before loss, each compiled when first recorded.
  const std::vector<std::unique_ptr<ComputePipeline>>& pipelines(bool with_before) const;
  mutable std::array<std::vector<std::unique_ptr<ComputePipeline>>, 2> pipelines_;
};

// The term passes of the assembly: all 11 terms at once, or in Private mode as many per pass as
// keep a lane's histogram (terms x TF entries) within `slots` (the device's
// private_limit(ctx, kPrivateHistogramSlots)).
std::vector<AssembleNormalEquationsKernel::TermPass> assemble_term_passes(ReductionMode mode, uint32_t tf_size,
                                                                          uint32_t slots = kPrivateHistogramSlots);

// Adds per-channel sums of squared and absolute colour differences and the voxel count to a
// TFM_LOSS_SLOTS-slot fixed-point accumulator; with `before_map` (the second field mapped onto
// the reference TF's entries) also the loss before optimization, in the same pass, to slots
// TFM_LOSS_SLOTS.. 2 TFM_LOSS_SLOTS - 1. Dispatches per range of at most `range_quads` quads
// (texel_range_quads) in workgroups of lane_workgroup_size(ctx, workgroup_size). Every choice
// gives the same bits (tests force splits and sizes).
class VoxelLossKernel {
 public:
  explicit VoxelLossKernel(Context& ctx, uint64_t range_quads = 0, uint32_t workgroup_size = 0);
  ~VoxelLossKernel();
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf, Buffer& accum,
              const FieldMapping* before_map = nullptr) const;

 private:
  const ComputePipeline& pipeline(bool with_before) const;  // compiled on first use
  Context& ctx_;
  uint64_t range_quads_;
  uint32_t workgroup_size_;
  mutable std::array<std::unique_ptr<ComputePipeline>, 2> pipelines_;
};

// Workgroups for a 1-D voxel kernel over `voxels` (each invocation loops over ~32 voxels).
uint32_t voxel_groups(const Context& ctx, uint64_t voxels);

// Workgroup size of a quad kernel whose lanes each keep their own sums or write their own voxels
// (voxel loss, residual map, the CGLS prepare and gather): `requested` if given, else one subgroup on a CPU device — which
// runs a workgroup on one thread and its invocations as coroutines between barriers (lavapipe,
// 41.5 M voxels, both voxel losses: 0.41 s in groups of 256, 0.19-0.21 s in groups of 8) — and
// TFM_VOXEL_WORKGROUP elsewhere. Throws std::invalid_argument naming `kernel` unless the size is
// a multiple of the subgroup size (quad_segments.glsl strides by it) within the device's limit.
uint32_t lane_workgroup_size(const Context& ctx, uint32_t requested, const char* kernel);
// Workgroups of `workgroup_size` for one dispatch over `voxels`: voxel_groups() at
// TFM_VOXEL_WORKGROUP; smaller groups get lanes of about `lane_voxels` voxels, but at least
// kPrivateMinGroups groups (lanes of `min_lane_voxels` or more) so that every core has work.
inline constexpr uint64_t kLaneVoxels = 4096;
uint32_t lane_groups(const Context& ctx, uint32_t workgroup_size, uint64_t voxels, uint64_t lane_voxels = kLaneVoxels,
                     uint64_t min_lane_voxels = 64);

// Kernels that read a chunk's voxels in quads, as RGBA32F texels (the assembly, its read bound,
// the voxel loss, the residual map, the CGLS gather), dispatch once per range of at most
// `range_quads` quads: `requested` if given (a multiple of 64, else std::invalid_argument naming
// `kernel`), else the device's maxTexelBufferElements rounded down to 64, so ranges start at
// multiples of 1024 bytes (every device's minTexelBufferOffsetAlignment is at most 256).
uint64_t texel_range_quads(const Context& ctx, uint64_t requested, const char* kernel);
// The same for kernels that see a voxel as one texel (an RGBA vector per voxel, or a field viewed
// from up to 64 texels before the range to meet the offset alignment): ranges of at most
// maxTexelBufferElements - 64 voxels; a `requested` beyond that also throws.
uint64_t voxel_texel_range_quads(const Context& ctx, uint64_t requested, const char* kernel);
struct QuadRange {
  size_t chunk = 0;
  uint64_t first = 0, voxels = 0;  // within the chunk
  // The texel view over the range's quads, from byte first * (bytes a voxel); a range of fewer
  // than 4 voxels has no quads, and its view is one voxel that is never read.
  VkFormat format = VK_FORMAT_R32G32B32A32_SFLOAT;
  uint64_t bytes = 0;
};
// The ranges of every chunk of `field`, in order (views in the field's format); of chunks of the
// given sizes and format.
std::vector<QuadRange> quad_ranges(const DeviceField& field, uint64_t range_quads);
std::vector<QuadRange> quad_ranges(std::span<const uint64_t> chunk_voxels, uint64_t range_quads,
                                   FieldFormat format = FieldFormat::Float32);
// The view of range `r`'s quads of `field`, in the field's format (a range of fewer than 4 voxels:
// one voxel, never read).
Binding quad_texels(const DeviceField& field, const QuadRange& r);
// The view of chunk `c` of `field` as one texel a voxel in its format (the kernels read a range's
// last voxel_count % 4 voxels through it, by their index in the chunk).
Binding voxel_texels(const DeviceField& field, size_t c);

// Decodes `slots` 32.32 fixed-point accumulators read back as 2*slots uint32 words.
std::vector<double> decode_fixed_point(const std::vector<uint32_t>& words);

}  // namespace tfm
