// Choosing how the voxel-reducing kernels sum their terms.
#include "tfmatch/kernels/reduction.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/shaders/shader_registry.h"
#include "tfmatch/shaders/shared_layout.h"

namespace tfm {

const char* reduction_mode_name(ReductionMode mode) {
  switch (mode) {
    case ReductionMode::Auto: return "auto";
    case ReductionMode::RunsShared: return "runs, shared memory";
    case ReductionMode::RunsGlobal: return "runs, global atomics";
    case ReductionMode::Private: return "private histograms";
  }
  return "?";
}

bool is_cpu_device(const Context& ctx) { return ctx.properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU; }

uint32_t private_limit(const Context& ctx, uint32_t cpu_limit) {
  return is_cpu_device(ctx) ? cpu_limit : std::max<uint32_t>(1, cpu_limit / kGpuPrivateBudgetDivisor);
}

Reduction Reduction::choose(const Context& ctx, const char* kernel, uint32_t tf_size, uint64_t shared_bytes,
                            const ReductionOptions& options, uint32_t private_max_bins) {
  check_table_size(tf_size);
  const bool shared_fits = shared_bytes <= ctx.limits().maxComputeSharedMemorySize;
  Reduction r;
  r.tf_size = tf_size;
  r.workgroups = options.workgroups;
  r.lane_voxels = options.lane_voxels;
  const std::string who = std::string(kernel) + ": ";
  r.int64 = options.atomics == AtomicWidth::Bits64 || (options.atomics == AtomicWidth::Auto && ctx.int64_atomics());
  if (r.int64 && !ctx.int64_atomics())
    throw std::runtime_error(who + "64-bit atomics requested but the device (or the host that created it) does not "
                                   "enable shaderInt64 with 64-bit buffer and shared atomics");
  r.mode = options.mode;
  if (r.mode == ReductionMode::Auto) {
    if (is_cpu_device(ctx) && tf_size <= private_max_bins && r.int64) r.mode = ReductionMode::Private;
    else r.mode = shared_fits ? ReductionMode::RunsShared : ReductionMode::RunsGlobal;
  }
  if (r.mode == ReductionMode::Private && tf_size > private_limit(ctx, private_max_bins))
    throw std::runtime_error(who + "private histograms hold at most " +
                             std::to_string(private_limit(ctx, private_max_bins)) + " TF entries on this device, not " +
                             std::to_string(tf_size));
  // Sums of two 32-bit words in private arrays take twice the gathers and scatters, and compile
  // slowly on lavapipe: private histograms are a 64-bit path only.
  if (r.mode == ReductionMode::Private && !r.int64)
    throw std::runtime_error(who + "private histograms need 64-bit integers and atomics");
  if (r.mode == ReductionMode::Private)
    r.workgroup_size = std::clamp<uint32_t>(ctx.subgroup_size(), 1, ctx.limits().maxComputeWorkGroupSize[0]);
  if (r.mode == ReductionMode::RunsShared && !shared_fits)
    throw std::runtime_error(who + std::to_string(tf_size) + " TF entries need " + std::to_string(shared_bytes) +
                             " bytes of shared memory; the device has " +
                             std::to_string(ctx.limits().maxComputeSharedMemorySize));
  return r;
}

uint64_t Reduction::lane_quads_max() const {
  const uint64_t reserve = 2ull * tf_size + kPrivateMaxBins + 16;
  return std::min<uint64_t>(32768, (kLaneLoopBudget - reserve) / std::max(1u, lane_loops_per_quad));
}

uint32_t Reduction::groups(const Context& ctx, uint64_t voxels) const {
  const uint32_t max_groups = ctx.limits().maxComputeWorkGroupCount[0];
  const uint64_t quads = voxels / 4;
  if (mode == ReductionMode::Private) {
    // Lanes take quads in segments of TFM_REDUCE_SEGMENT_STEPS (quad_segments.glsl), so a lane's
    // share is up to 64 quads over quads / lanes: kLaneLoopBudget's margin below 65535 holds them.
    const uint64_t lanes = (quads + lane_quads_max() - 1) / lane_quads_max();
    const uint64_t budget_groups = (lanes + workgroup_size - 1) / workgroup_size;
    if (workgroups)
      return static_cast<uint32_t>(std::clamp<uint64_t>(std::max<uint64_t>(workgroups, budget_groups), 1, max_groups));
  }
  if (workgroups) return std::min(workgroups, max_groups);
  if (mode != ReductionMode::Private) return voxel_groups(ctx, voxels, lane_voxels ? lane_voxels : kVoxelLaneVoxels);
  const uint64_t per_lane = std::clamp<uint64_t>(16ull * tf_size, 2048, lane_quads_max());
  uint64_t groups = (quads / per_lane + workgroup_size) / workgroup_size;
  // Smaller volumes: more, shorter lanes (down to 4 N quads each, at least 256), so that up to
  // kPrivateMinGroups workgroups keep every core of a CPU device busy.
  const uint64_t min_per_lane = std::max<uint64_t>(256, 4ull * tf_size);
  groups = std::max(groups, std::min<uint64_t>(kPrivateMinGroups, quads / (min_per_lane * workgroup_size)));
  return static_cast<uint32_t>(std::clamp<uint64_t>(groups, 1, max_groups));
}

uint32_t Reduction::shader_mode() const {
  // The three kernels share these values (shared_layout.h).
  return mode == ReductionMode::Private      ? TFM_REDUCE_PRIVATE
         : mode == ReductionMode::RunsShared ? TFM_REDUCE_RUNS_SHARED
                                             : TFM_REDUCE_RUNS_GLOBAL;
}

PipelineDesc Reduction::pipeline_desc(const char* shader, std::vector<uint32_t> binding_counts,
                                      uint32_t push_bytes) const {
  PipelineDesc desc;
  desc.shader = int64 ? std::string(shader) + "_int64" : std::string(shader);
  desc.binding_counts = std::move(binding_counts);
  desc.push_constant_bytes = push_bytes;
  desc.workgroup_size = workgroup_size;
  desc.spirv = shader_spirv(desc.shader);
  return desc;
}

}  // namespace tfm
