// Wrappers of the DiffDVR kernels: the forward pass (render_image.comp in its DiffDVR state
// mode) writes each pixel's final state (C, T) and k_stop for a batch of cameras; the backward
// pass (diffdvr_backward.comp) re-marches from that state and adds the image loss and its TF
// gradient to fixed-point accumulators. Both take the renderer's push block (make_render_push of render_image.h).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/model/image_loss.h"
#include "tfmatch/shaders/diffdvr_layout.h"

namespace tfm {

class Context;



class DiffDvrForwardKernel {
 public:
  // Throws std::runtime_error when the field needs more buffers than the kernel binds.
  // `max_part_samples` > 0: rays longer than that are marched in parts on any device (tests).
  DiffDvrForwardKernel(Context& ctx, uint32_t field_chunks, uint32_t max_part_samples = 0);
  // Records the pass over rows [row_begin, row_begin + row_count) of every view of `push`: one
  // dispatch, or on a device that limits an invocation's loops, rays longer than that in parts
  // (march_parts), as the renderer's. `state` holds width*height*views vec4 (C, T), `stop` as
  // many uints. Throws std::invalid_argument when a buffer or the field's chunking does not fit.
  void record(CommandBatch& batch, const DeviceField& field, const Buffer& tf, const Buffer& views,
              gpu::RenderPush push, Buffer& state, Buffer& stop, uint32_t row_begin, uint32_t row_count) const;

 private:
  const Context& ctx_;
  uint32_t chunks_;
  uint32_t max_part_samples_;
  SharedPipeline pipeline_;
};

// TF entries up to which CPU devices take the backward pass's private-histogram build (a vec4 per
// entry and lane: 16 KiB per lane at 1024).
inline constexpr uint32_t kDiffDvrPrivateMaxBins = 1024;

// How the backward pass's runs modes march a ray back (diffdvr_backward.comp, backpropagate_runs):
// Nested, a loop of runs around a loop of samples, keeps the flushes out of the code every sample
// passes (GPUs); Flat, one loop with the flush inside, costs one loop iteration a sample (devices
// that count them, Context::loop_iteration_limit). The same runs and sums: the same bits.
enum class RunsMarch { Auto, Nested, Flat };

class DiffDvrBackwardKernel {
 public:
  // How the gradient is summed (diffdvr_backward.comp's header explains each): Auto takes Private
  // on CPU devices with subgroup arithmetic up to kDiffDvrPrivateMaxBins entries, else RunsShared
  // when the slots of `tf_size` entries fit shared memory, else RunsGlobal. A forced mode the
  // device cannot run throws std::runtime_error naming what is missing. The runs modes give the
  // same bits; Private sums in another float grouping (deterministic too).
  // `march`: how a runs mode marches its rays (RunsMarch; Auto: Flat on devices with a loop limit,
  // else Nested; ignored by Private). `max_part_samples` > 0: a Flat march takes rays longer than
  // that back in parts on any device (tests; record()).
  DiffDvrBackwardKernel(Context& ctx, uint32_t field_chunks, uint32_t tf_size, ImageLoss loss,
                        ReductionMode mode = ReductionMode::Auto, RunsMarch march = RunsMarch::Auto,
                        uint32_t max_part_samples = 0);
  uint32_t tf_size() const { return tf_size_; }
  uint32_t slots() const { return TFM_DIFFDVR_SLOTS(tf_size_); }  // accumulator bytes: 8 per slot
  ReductionMode mode() const { return mode_; }
  // Why `mode` cannot run on this device for `tf_size` entries, or "" when it can (Auto: "").
  static std::string unsupported(const Context& ctx, uint32_t tf_size, ReductionMode mode);
  // The mode a kernel for `tf_size` entries takes when asked for `mode` (resolves Auto). With
  // `max_steps` (the rays' samples, 0: unknown), Auto leaves Private, whose lanes march
  // TFM_DIFFDVR_PRIVATE_PIXELS rays each, for the runs modes when those rays are longer than the
  // device lets one invocation loop (Context::loop_iteration_limit).
  static ReductionMode choose(const Context& ctx, uint32_t tf_size, ReductionMode mode = ReductionMode::Auto,
                              uint32_t max_steps = 0);
  RunsMarch march() const { return march_; }
  // What record() checks in `mode` (Private or a runs mode) for `tf_size` entries: the loop
  // iterations one invocation's march back costs a sample (Private: its rays; a runs mode: 1
  // marched flat, at most 10 nested on llvmpipe's SIMD vectors of 8 lanes, whose inner loop steps
  // while any lane is still in its run), and its other loops.
  static uint32_t loops_per_sample(ReductionMode mode, RunsMarch march);
  static uint64_t other_loops(ReductionMode mode, uint32_t tf_size);
  bool uses_shared_memory() const { return mode_ == ReductionMode::RunsShared; }
  // Adds the loss of (state vs target) over rows [row_begin, row_begin + row_count) of every view
  // and its gradient w.r.t. `tf` to `accum`. `state`/`stop` are the forward pass's output for
  // (field, tf, views, push); `target` has the same layout. On a device that limits an
  // invocation's loops, a runs mode marched flat (RunsMarch; Auto's choice there) takes rays
  // longer than that back in parts (march_parts, from the rays' ends), keeping each ray's state
  // and adjoints between them in `resume`, of at least resume_bytes() (its runs are flushed at the
  // parts' edges: other float groupings than whole rays). Throws std::invalid_argument when a
  // buffer (`resume` included), the TF size or the chunking does not fit, std::runtime_error when
  // the rays of Private or of a nested march are longer than the device lets one invocation
  // march back (check_march_loops).
  void record(CommandBatch& batch, const DeviceField& field, const Buffer& tf, const Buffer& views,
              gpu::RenderPush push, const Buffer& state, const Buffer& stop, const Buffer& target, Buffer& accum,
              uint32_t row_begin, uint32_t row_count, Buffer* resume = nullptr) const;
  // The bytes record() needs in `resume` for `push`: 0 where it marches whole rays, else 32 a
  // pixel of every view (the state (C, T) and its adjoints).
  uint64_t resume_bytes(const gpu::RenderPush& push) const;

 private:
  const Context& ctx_;
  uint32_t chunks_;
  uint32_t tf_size_;
  ReductionMode mode_;
  RunsMarch march_;
  uint32_t max_part_samples_;
  SharedPipeline pipeline_;
};

// The exact total of signed 32.32 fixed-point accumulators (two's complement, low word first)
// read back from several passes. Integer parts and fractions are summed apart in 64-bit
// integers (exact for < 2^31 passes of values below 2^31), so the total, and the double it is
// rounded to once, do not depend on how the work was split into passes.
class FixedPointTotals {
 public:
  explicit FixedPointTotals(size_t slots) : whole_(slots, 0), fraction_(slots, 0) {}
  void add(const uint32_t* words);  // 2 * slots words
  std::vector<double> values() const;

 private:
  std::vector<int64_t> whole_, fraction_;
};

}  // namespace tfm
