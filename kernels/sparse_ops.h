// The matrix-free operators of the voxel system: per-voxel vectors (TF coordinates and an RGBA
// vector, chunked to fit storage buffers), and the kernels that prepare them, gather q = S x and
// scatter s = S^T r into deterministic signed fixed-point accumulators.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/shaders/solver_layout.h"

namespace tfm {

class Context;

// Per-voxel vectors of the matrix-free solvers over a pair of fields: the TF coordinate of each
// voxel (4 bytes) and one RGBA vector (16 bytes; b, then the CGLS residual). Chunks are sized so
// that an RGBA chunk fits one storage buffer and lies inside one chunk of the fields.
// A kernel's pipeline and its TFM_WEIGHTED variant (weighted voxel vectors: the shader
// "<stem>_weighted", its extra bindings after the plain ones), the variant built when weighted
// vectors first come.
class WeightedPipelines {
 public:
  // `weighted_counts`: the variant's bindings; `weighted_texels`: which of its extra bindings are
  // uniform texel buffers (the others storage buffers).
  WeightedPipelines(Context& ctx, PipelineDesc plain, std::vector<uint32_t> weighted_counts,
                    std::initializer_list<uint32_t> weighted_texels = {});
  const ComputePipeline& get(bool weighted) const;

 private:
  Context& ctx_;
  SharedPipeline plain_;
  PipelineDesc weighted_desc_;
  mutable SharedPipeline weighted_;
};

class VoxelVectors {
 public:
  // `max_chunk_voxels` (0: device limit) forces smaller chunks in tests. Throws
  // std::invalid_argument when the fields differ in size or chunking, std::runtime_error when no
  // chunk size fits the device (the message says how large the fields and the limit are).
  // `weighted`: also a row scale per voxel (sqrt of its weight), which sparse_prepare writes from a
  // weights field and the gather and scatter multiply each voxel's row by (weighted least squares).
  VoxelVectors(Context& ctx, const DeviceField& ref, const DeviceField& opt, uint64_t max_chunk_voxels = 0,
               bool weighted = false);
  bool weighted() const { return !scale_.empty(); }
  const Buffer& scale(size_t c) const;  // std::logic_error for unweighted vectors

  uint64_t voxel_count() const { return voxels_; }
  uint64_t chunk_voxels() const { return chunk_voxels_; }
  size_t chunk_count() const { return coord_.size(); }
  uint64_t chunk_begin(size_t c) const { return c * chunk_voxels_; }
  uint64_t chunk_size(size_t c) const;
  std::vector<uint64_t> chunk_sizes() const;  // of every chunk, in order
  // The chunk of the input fields that holds chunk c, and c's first voxel inside it.
  size_t field_chunk(size_t c) const { return size_t(chunk_begin(c) / field_chunk_voxels_); }
  uint64_t field_offset(size_t c) const { return chunk_begin(c) % field_chunk_voxels_; }
  const Buffer& coord(size_t c) const { return coord_[c]; }
  Buffer& rgba(size_t c) { return rgba_[c]; }
  const Buffer& rgba(size_t c) const { return rgba_[c]; }

  // Reads every chunk back (tests, small problems).
  std::vector<float> read_coords(Context& ctx) const;
  std::vector<float> read_rgba(Context& ctx) const;  // 4 floats per voxel

 private:
  uint64_t voxels_ = 0;
  uint64_t chunk_voxels_ = 0;
  uint64_t field_chunk_voxels_ = 0;
  std::vector<Buffer> coord_;
  std::vector<Buffer> rgba_;
  std::vector<Buffer> scale_;
};

// Writes coordinates and b = clamp(T_r(F_r), 0, 1) of every voxel (TFM_NO_DATA / 0 where either
// field has no data). Dispatches per range of at most `range_quads` quads
// (voxel_texel_range_quads) in workgroups of lane_workgroup_size(ctx, workgroup_size).
class SparsePrepareKernel {
 public:
  explicit SparsePrepareKernel(Context& ctx, uint64_t range_quads = 0, uint32_t workgroup_size = 0);
  // With `weights` (weighted vectors only: a float32 field chunked as the fields) b and the rows
  // are scaled by sqrt(weight): the vectors of the weighted least-squares problem.
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, VoxelVectors& vectors,
              const DeviceField* weights = nullptr) const;

 private:
  Context& ctx_;
  uint64_t range_quads_;
  uint32_t workgroup_size_;
  std::unique_ptr<WeightedPipelines> pipelines_;
};

// q = S x (x: N RGBA entries; weighted vectors: each row times its voxel's scale). With `write_out` stores q in the vectors' RGBA chunks; with
// `accumulate_norm` adds ||q_c||^2 to TFM_GATHER_NORM_SLOTS unsigned 32.32 slots, of q / p_scale
// (from a CGLS state buffer) when `scaled` — and then does nothing once every channel of that
// state has stopped. Dispatches per range of at most `range_quads` quads (texel_range_quads) in
// workgroups of lane_workgroup_size(ctx, workgroup_size) (voxel_pair.h); every choice gives the
// same bits (tests force them).
class SparseGatherKernel {
 public:
  SparseGatherKernel(Context& ctx, bool write_out, bool accumulate_norm, bool scaled = false, uint64_t range_quads = 0,
                     uint32_t workgroup_size = 0);
  // `state` is required when scaled, ignored otherwise.
  void record(CommandBatch& batch, VoxelVectors& vectors, uint32_t tf_size, const Buffer& x, Buffer& norm_accum,
              const Buffer* state = nullptr) const;

 private:
  Context& ctx_;
  bool scaled_;
  uint64_t range_quads_;
  uint32_t workgroup_size_;
  std::unique_ptr<WeightedPipelines> pipelines_;
  Buffer dummy_state_;
};

// s += S^T r (weighted vectors: each row times its voxel's scale), r = the vectors' RGBA chunks, into 4N signed slots (TFM_FIXED_SLOT_WORDS words each:
// signed_accumulator_bytes(N)). With `update_residual` first r -= alpha (S p), alpha from the
// CGLS state. Dispatches per range of at most `range_quads` quads (voxel_texel_range_quads: r is
// read as a texel per voxel). The same bits for every
// ReductionOptions and range split; throws as Reduction::choose when a forced one does not fit
// the device.
class SparseScatterKernel {
 public:
  SparseScatterKernel(Context& ctx, uint32_t tf_size, bool update_residual, ReductionOptions options = {},
                      uint64_t range_quads = 0);
  ReductionMode mode() const { return reduction_.mode; }
  bool int64_atomics() const { return reduction_.int64; }
  // Plain S^T r.
  void record(CommandBatch& batch, VoxelVectors& vectors, Buffer& accum) const;
  // The CGLS residual update and S^T r of the updated residual.
  void record_update(CommandBatch& batch, VoxelVectors& vectors, const Buffer& p, const Buffer& state,
                     Buffer& accum) const;

 private:
  void record_ranges(CommandBatch& batch, VoxelVectors& vectors, const Buffer& p, const Buffer& state,
                     Buffer& accum) const;
  Context& ctx_;
  uint32_t tf_size_;
  bool update_;
  uint64_t range_quads_;
  Reduction reduction_;
  std::unique_ptr<WeightedPipelines> pipelines_;
  Buffer dummy_p_, dummy_state_;
};

// Bytes of 4N signed 32.32 accumulators.
uint64_t signed_accumulator_bytes(uint32_t tf_size);
// Decodes signed accumulators read back as uint32 words (two's complement 32.32, as FixedPointTotals).
std::vector<double> decode_signed_fixed_point(const std::vector<uint32_t>& words);
// Whether 4N signed slots fit the device's workgroup-shared memory.
bool signed_slots_fit_shared(const Context& ctx, uint32_t tf_size);

}  // namespace tfm
