// GPU passes over a pair of device fields: assemble the normal equations, measure voxel loss.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/assemble_normal_equations.h"
#include "tfmatch/kernels/voxel_loss.h"
#include "tfmatch/model/normal_equations_system.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm {

// Accumulates the normal equations over any number of field pairs (streamed chunks of one large
// volume, say) and returns them in double precision. Deterministic: the same bits on every run,
// for every ReductionOptions (tests force each mode and atomic width).
class GpuNormalEquations {
 public:
  GpuNormalEquations(Context& ctx, uint32_t tf_size, ReductionOptions options = {});
  void reset();
  // Adds the voxels of (ref, opt); returns the GPU time in ms (-1 without timestamps). With
  // `before_map` (the second field mapped onto the reference TF's entries) the system also
  // carries the voxel loss before optimization (NormalEquations::before); every add() of one
  // accumulation must then pass it (std::invalid_argument otherwise). With `weights` (a float32
  // field like `ref`, values in [0, 1]) the system is the weighted one, sum_i w_i (s_i x - b_i)^2
  // (AssembleNormalEquationsKernel::record).
  double add(const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
             const FieldMapping& opt_map, const Buffer& ref_tf, const FieldMapping* before_map = nullptr,
             const DeviceField* weights = nullptr);
  NormalEquations result() const;
  // The exact totals: TFM_ASSEMBLE_SLOTS(N) unsigned 32.32 fixed-point numbers (integer value
  // = total * 2^32, modulo 2^64).
  std::vector<uint64_t> fixed_point_slots() const;
  // The system such totals stand for, with the loss before optimization when `with_before` (the
  // assembly summed it: add() was given a before mapping). result() is decode(fixed_point_slots())
  // of its own adds; the totals of several processes added as integers give the bits of one
  // process's assembly.
  NormalEquations decode(std::span<const uint64_t> slots, bool with_before) const;
  const AssembleNormalEquationsKernel& kernel() const { return kernel_; }

 private:
  Context& ctx_;
  AssembleNormalEquationsKernel kernel_;
  Buffer accum_;
  uint32_t adds_ = 0;          // add() calls since reset()
  bool with_before_ = false;   // whether they passed a before mapping
};

struct VoxelLoss {
  std::array<double, 4> squared{};   // per channel sum of squared differences
  std::array<double, 4> absolute{};  // per channel sum of absolute differences (NaN: not measured)
  uint64_t voxels = 0;
  // Root mean square over all RGBA components.
  double rmse() const;
  // Mean absolute difference over all RGBA components.
  double mae() const;
};

// The losses in VoxelLossKernel's accumulators (TFM_LOSS_SLOTS slots each) read back as words.
std::vector<VoxelLoss> decode_voxel_losses(const std::vector<uint32_t>& words);

// Voxel loss between T_r(F_r) and T_o(F_o) on the GPU.
VoxelLoss voxel_loss_gpu(Context& ctx, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
                         const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf,
                         double* gpu_ms = nullptr);

// The voxel losses of a fit, both in one pass over the voxels: `before`, the second field shown
// with the reference TF (`before_map` maps it onto the reference TF's entries), and `after`, with
// `opt_tf` through `opt_map`. Each is what voxel_loss_gpu() gives, bit for bit. `kernel`: one to
// use (prepared ahead: VoxelLossKernel::prepare(true)), else one is made here.
struct VoxelLosses {
  VoxelLoss before, after;
};
VoxelLosses voxel_losses_gpu(Context& ctx, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
                             const FieldMapping& before_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                             const Buffer& opt_tf, double* gpu_ms = nullptr, const VoxelLossKernel* kernel = nullptr);

// The voxel loss of the TF `rgba` (N entries as 4N floats, the values the kernels read) from the
// assembled system alone: per channel ||S x - b||^2 = x^T M x - 2 x^T S^T b + b^T b, no pass over
// the voxels. Absolute differences do not follow from M: they are NaN. Throws
// std::invalid_argument when the TF size differs from the system's.
VoxelLoss voxel_loss_from_system(const NormalEquations& eq, std::span<const float> rgba);
// The voxel loss before optimization, the second field shown with the reference TF `ref_rgba`:
// eq.before when the system carries it (a reference TF of another size), else
// voxel_loss_from_system(eq, ref_rgba). Throws std::invalid_argument when neither applies.
VoxelLoss voxel_loss_before(const NormalEquations& eq, std::span<const float> ref_rgba);

// Uploads a TF table: N RGBA entries as 4N floats (the vec4 array every kernel reads).
// Throws std::invalid_argument unless the size is a multiple of 4 and at least 2 entries.
Buffer upload_tf(Context& ctx, std::span<const float> rgba, const std::string& name);
// The same for a TF table (host/model/transfer_function.h).
inline Buffer upload_tf(Context& ctx, const TransferFunction& tf, const std::string& name) {
  const std::vector<float> v = tf.as_floats();
  return upload_tf(ctx, std::span<const float>(v), name);
}

}  // namespace tfm
