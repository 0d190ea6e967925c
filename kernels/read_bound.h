// The read bound of the normal-equation assembly (shaders/field_pair_read.comp): both fields read
// with the assembly's access pattern and nothing computed but an integer sum of the values' bits.
// `tfmatch bench` reports the assembly as a fraction of this speed; the sums prove every voxel
// was read once (field_pair_bit_sums is the CPU reference).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>

#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"

namespace tfm {

class Buffer;
class CommandBatch;
class Context;

// The sums modulo 2^32 of the bit patterns of every value of `ref` and of `opt`.
std::array<uint32_t, 2> field_pair_bit_sums(std::span<const float> ref, std::span<const float> opt);

class FieldPairReadKernel {
 public:
  // `range_quads`: quads per dispatch (a texel view each), a multiple of 64; 0: the device's
  // maxTexelBufferElements, as the assembly (tests force splits). `lane_voxels` 0: this device's
  // layout of the voxel kernels' lanes (lane_workgroup_size, lane_groups: on a CPU device groups of
  // one subgroup with long lanes, as its assembly's private histograms; on a GPU the run modes'
  // groups of TFM_VOXEL_WORKGROUP); else the run modes' groups with lanes of that many voxels
  // (voxel_groups; ReductionOptions::lane_voxels), whatever the device.
  explicit FieldPairReadKernel(Context& ctx, uint64_t range_quads = 0, uint64_t lane_voxels = 0);
  ~FieldPairReadKernel();
  // Records reading every voxel of both fields (same size and chunking) and adding the two bit
  // sums to `result` (two uint32, which the caller zeroes).
  void record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt, Buffer& result) const;
  // Runs it alone; `gpu_ms` receives the GPU time where the device has timestamps (else -1).
  std::array<uint32_t, 2> run(const DeviceField& ref, const DeviceField& opt, double* gpu_ms = nullptr) const;

 private:
  Context& ctx_;
  uint64_t range_quads_;
  uint64_t lane_voxels_;
  uint32_t workgroup_size_;
  SharedPipeline pipeline_;
};

}  // namespace tfm
