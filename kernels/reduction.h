// How the voxel-reducing kernels (normal-equation assembly, S^T r of CGLS, the gradient of
// gradient descent) sum their terms: the mode, the atomic width and the workgroups a dispatch
// uses, chosen from the device or forced by a caller (the tests force every combination; all
// give the same bits). The shaders' header comments explain each mode.
#pragma once

#include <cstdint>
#include <vector>

#include "tfmatch/engine/pipeline.h"
#include "tfmatch/shaders/shared_layout.h"  // TFM_VOXEL_WORKGROUP

namespace tfm {

class Context;

enum class ReductionMode {
  Auto,        // Private on CPU devices with 64-bit atomics up to kPrivateMaxBins TF entries (the
               // assembly: kAssemblePrivateMaxBins), else
               // RunsShared if it fits, else RunsGlobal
  RunsShared,  // register runs per lane, flushed to workgroup-shared accumulators
  RunsGlobal,  // register runs per lane, flushed to the global accumulators
  Private,     // a private histogram per lane, added to the global accumulators at the end (needs
               // 64-bit atomics)
};
enum class AtomicWidth {
  Auto,    // 64-bit where the context has them (Context::int64_atomics)
  Bits32,  // two 32-bit words with carry: any Vulkan device
  Bits64,  // one 64-bit word per slot
};
struct ReductionOptions {
  ReductionMode mode = ReductionMode::Auto;
  AtomicWidth atomics = AtomicWidth::Auto;
  uint32_t workgroups = 0;  // per dispatch; 0: from the chunk size (tests force counts)
  uint32_t range_quads = 0;  // assembly: quads per dispatch (texel view); 0: the device's
                             // maxTexelBufferElements (tests force splits)
  uint32_t lane_voxels = 0;  // run modes: voxels per lane (voxel_groups); 0: kVoxelLaneVoxels
};
const char* reduction_mode_name(ReductionMode mode);

// TF entries up to which CPU devices take the private-histogram path (each lane holds its
// kernel's sums per entry: 4 for S^T r and the gradient, 32 KiB per lane at 1024). The assembly,
// which splits its terms into passes, takes it up to kAssemblePrivateMaxBins.
inline constexpr uint32_t kPrivateMaxBins = 1024;
inline constexpr uint32_t kAssemblePrivateMaxBins = 4096;
// 64-bit sums a lane's private histogram holds at most (the assembly's 11 terms of 1024 entries:
// 88 KiB per lane, in a CPU core's L2; lavapipe keeps a SIMD vector's lanes together, 704 KiB
// of its thread's stack). Kernels with more per entry split their terms into passes. Measured
// with larger budgets (lavapipe, LLVM 15, 8 lanes): 11 x 2048 made N = 4096 1.5x faster, but
// from 11 x 3900 sums per lane (2.7 MB per SIMD vector) on the assembly returned wrong sums
// without any error (11 x 3800 still right; a larger stack limit changed nothing) — only when
// two or more workgroups ran (1.76 M voxels; not at 0.4 M, one workgroup), so the budget keeps a
// wide margin below a limit that is not understood, and the tests run its edge on two workgroups.
inline constexpr uint32_t kPrivateHistogramSlots = 11 * 1024;
// The budgets above are for CPU devices. GPUs get an eighth of them: Auto never takes private
// histograms there (they are a cross-check of the other paths), and a GPU compiler puts a large
// private array in local memory or refuses it (measured on an H100, NVIDIA driver 580: the
// assembly with 11 x 701 sums per invocation, 61.7 KiB, failed vkCreateComputePipelines with
// VK_ERROR_UNKNOWN; 11 x 64 built and matched the CPU).
inline constexpr uint32_t kGpuPrivateBudgetDivisor = 8;
// Loop iterations one lane of a Private dispatch may run in all. llvmpipe (lavapipe, the CPU device
// Private is for) keeps one counter per invocation, set to 65535 and decreased at the end of every
// iteration of every loop (nested ones too, and once more as a loop exits); at 0 every loop of the
// invocation ends, silently. The margin covers the lane's loops outside its walk (zeroing and
// adding its histogram, 2 N + 2, and a reference-TF cache of up to kPrivateMaxBins + 1, in
// lane_quads_max()) and a lane's share of quads rounding up by less than a segment.
inline constexpr uint64_t kLaneLoopBudget = 60000;
// Workgroups a Private dispatch over a small volume is split into at least (when each lane still
// covers its minimum of voxels), so that every core of a CPU device has work.
inline constexpr uint64_t kPrivateMinGroups = 16;
// A CPU-device limit of entries or slots (cpu_limit) as it holds on this device.
uint32_t private_limit(const Context& ctx, uint32_t cpu_limit);

// A resolved choice for one kernel.
struct Reduction {
  ReductionMode mode = ReductionMode::RunsShared;
  bool int64 = false;
  uint32_t workgroups = 0;  // forced count, or 0
  uint32_t lane_voxels = 0;  // run modes: voxels per lane, or 0 for kVoxelLaneVoxels
  uint32_t tf_size = 0;
  // Invocations per workgroup: TFM_VOXEL_WORKGROUP, but one subgroup for Private (a CPU device
  // runs a workgroup on one thread, and a lane's cost is its histogram's flush: more, smaller
  // groups spread the same lanes over every core).
  uint32_t workgroup_size = TFM_VOXEL_WORKGROUP;
  // Loop iterations a lane's Private walk runs per quad (1; tf_residual_walk.glsl's loop over a
  // quad's four voxels makes it TFM_RESIDUAL_WALK_LOOPS_PER_QUAD): groups() keeps every lane's
  // walk within kLaneLoopBudget.
  uint32_t lane_loops_per_quad = 1;

  // Resolves `options` for a kernel whose shared accumulators take `shared_bytes` for `tf_size`
  // entries and whose private histograms hold up to private_max_bins entries on a CPU device
  // (private_limit() on others). Throws std::runtime_error naming what is missing when a forced
  // mode or width does not fit the device (shared memory, 64-bit atomics, the private limit,
  // Private with 32-bit).
  static Reduction choose(const Context& ctx, const char* kernel, uint32_t tf_size, uint64_t shared_bytes,
                          const ReductionOptions& options, uint32_t private_max_bins = kPrivateMaxBins);
  // Workgroups of workgroup_size for one dispatch over `voxels`: the forced count, else
  // voxel_groups() for the run modes (lanes of lane_voxels) and, for Private, enough lanes that
  // each covers about 16 N quads (its histogram is added to memory once, so lanes must cover many
  // voxels) but at most lane_quads_max(), and up to kPrivateMinGroups workgroups of shorter lanes
  // when the volume is small (every core of a CPU device gets work). A forced Private count is
  // raised where its lanes would exceed lane_quads_max().
  uint32_t groups(const Context& ctx, uint64_t voxels) const;
  // Private: the most quads one lane walks, 32768 or what kLaneLoopBudget leaves at
  // lane_loops_per_quad loop iterations a quad.
  uint64_t lane_quads_max() const;
  // The TFM_*_RUNS_SHARED / _RUNS_GLOBAL / _PRIVATE value of the shaders' MODE constant.
  uint32_t shader_mode() const;
  // A pipeline of `shader` (its _int64 build when this reduction uses 64-bit atomics) over
  // workgroup_size invocations; the caller adds the specialization constants (with
  // TFM_SPEC_WORKGROUP_X = workgroup_size).
  PipelineDesc pipeline_desc(const char* shader, std::vector<uint32_t> binding_counts, uint32_t push_bytes) const;
};

bool is_cpu_device(const Context& ctx);

}  // namespace tfm
