// Wrapper of shaders/assemble_normal_equations.comp: the deterministic assembly of M, S^T b and
// b^T b (DESIGN.md), its pipelines per term pass, and one dispatch per range of a field chunk.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <tuple>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/model/field_mapping.h"

namespace tfm {

class Context;

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
  // Records one dispatch per chunk and texel range (barriers between them), a workgroup row per
  // term pass. With `before_map` (the second field mapped onto the reference TF's entries:
  // tf_size of ref_map) the kernel also adds the loss before optimization to slots
  // [6N+4, 6N+8) (shared_layout.h). With `weights` (a float32 field of the same size and chunking, values in [0, 1]) every term
  // of voxel i is multiplied by weights[i], rounded once to float (the weighted least squares of
  // visibility weights, kernels/visibility_weights.h); the voxel count stays a count.
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, Buffer& accum,
              const FieldMapping* before_map = nullptr, const DeviceField* weights = nullptr) const;

  // The same for two images of one extent read in place (the shader's TFM_FIELD_IMAGE variant,
  // voxel i at texel (i % nx, i / nx % ny, i / (nx ny))): the same bits as the same values in
  // buffers. Throws std::invalid_argument for missing views or differing or empty extents.
  void record(CommandBatch& batch, const ImageFieldView& ref, const ImageFieldView& opt, const FieldMapping& ref_map,
              const FieldMapping& opt_map, const Buffer& ref_tf, Buffer& accum,
              const FieldMapping* before_map = nullptr) const;

  // Which of the 11 bin terms one pass adds (shaders/assemble_normal_equations.comp): pass p is
  // row p of every dispatch; all passes but the last add the same number of terms.
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
  // Without and with the before loss and weights, each compiled when first recorded (one pipeline
  // for all term passes: they are its workgroup rows); for images also per x and y size
  // (specialization constants).
  const ComputePipeline& pipeline(bool with_before, bool weighted) const;
  const ComputePipeline& image_pipeline(bool with_before, uint32_t nx, uint32_t ny) const;
  SharedPipeline make_pipeline(bool with_before, const VkExtent3D* image, bool weighted) const;
  gpu::VoxelPairPush push_for(const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                              Buffer& accum, const FieldMapping* before_map) const;
  mutable std::array<SharedPipeline, 4> pipelines_;  // [with_before + 2 weighted]
  mutable std::map<std::tuple<bool, uint32_t, uint32_t>, SharedPipeline> image_pipelines_;
};

// The term passes of the assembly: all 11 terms at once, or in Private mode the fewest passes that
// keep a lane's histogram (terms x TF entries) within `slots` (the device's
// private_limit(ctx, kPrivateHistogramSlots)), each of the same number of terms but the last.
std::vector<AssembleNormalEquationsKernel::TermPass> assemble_term_passes(ReductionMode mode, uint32_t tf_size,
                                                                          uint32_t slots = kPrivateHistogramSlots);

}  // namespace tfm
