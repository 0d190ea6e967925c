// GPU passes over a pair of device fields: assemble the normal equations, measure voxel loss.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>

#include "context.h"
#include "device_field.h"
#include "normal_equations_system.h"
#include "voxel_pair.h"

namespace tfm {

// Accumulates the normal equations over any number of field pairs (streamed chunks of one large
// volume, say) and returns them in double precision. Deterministic: same bits on every run.
class GpuNormalEquations {
 public:
  GpuNormalEquations(Context& ctx, uint32_t tf_size, bool force_global_atomics = false, uint32_t run = 0);
  void reset();
  // Adds the voxels of (ref, opt); returns the GPU time in ms (-1 without timestamps).
  double add(const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
             const FieldMapping& opt_map, const Buffer& ref_tf);
  NormalEquations result() const;
  const AssembleNormalEquationsKernel& kernel() const { return kernel_; }

 private:
  Context& ctx_;
  AssembleNormalEquationsKernel kernel_;
  Buffer accum_;
};

struct VoxelLoss {
  std::array<double, 4> squared{};   // per channel sum of squared differences
  std::array<double, 4> absolute{};  // per channel sum of absolute differences
  uint64_t voxels = 0;
  // Root mean square over all RGBA components.
  double rmse() const;
  // Mean absolute difference over all RGBA components.
  double mae() const;
};

// Voxel loss between T_r(F_r) and T_o(F_o) on the GPU.
VoxelLoss voxel_loss_gpu(Context& ctx, const DeviceField& ref, const DeviceField& opt, const FieldMapping& ref_map,
                         const FieldMapping& opt_map, const Buffer& ref_tf, const Buffer& opt_tf,
                         double* gpu_ms = nullptr);

// Uploads a TF table: N RGBA entries as 4N floats (the vec4 array every kernel reads).
// Throws std::invalid_argument unless the size is a multiple of 4 and at least 2 entries.
Buffer upload_tf(Context& ctx, std::span<const float> rgba, const std::string& name);

}  // namespace tfm
