// Correlation fields of an ensemble (shaders/correlation_*.comp): per voxel, a dependence measure
// between the member series at a reference point and the member series at that voxel.
//
// An ensemble in memory is member-major: member m's value at voxel v is values[m * voxel_count + v]
// (each member a whole field, x fastest), so one invocation per voxel reads consecutive addresses.
// Results are deterministic: the same bits on every run, chunking and device.
//
// Conventions every measure shares (the CPU references in host/reference/correlation_cpu.h too):
// - NaN in the reference series or in a voxel's series (any member) gives NaN at that voxel; for
//   pearson and mi-binned so does ±Inf (needs_finite_members: an infinite mean, bins over an
//   infinite range). The rank measures and mi-kraskov order ±Inf as any other value.
// - A constant series (either one): pearson, spearman and kendall give NaN (no variance);
//   mi-binned, mi-kraskov and mi-coefficient give 0 (a constant carries no information).
// - At least 3 members and at most kMaxCorrelationMembers (std::invalid_argument otherwise).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tfmatch/model/correlation_measure.h"  // the measures, their parameters, EnsembleView

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/device_field.h"

namespace tfm {

class Context;
struct CorrelationReference;

// The reference series' tables on the device (values, order, tie groups, count table), as the
// kernels read them; written by record_correlation_tables.
struct CorrelationTables {
  Buffer values, order, group, table;
};
// Records the writes of `ref`'s tables into `tables` (each grown when too small) inside `batch`.
void record_correlation_tables(CommandBatch& batch, Context& ctx, const CorrelationReference& ref,
                               CorrelationTables& tables);

// An ensemble already on the device, as CorrelationKernel::record reads it: either `buffer`,
// holding members x `voxels` values of `format` member-major (member m's voxel v at m * voxels + v;
// an embedder's buffer through Buffer::adopt), or `images`, one 3D image per member (mip 0,
// layer 0; `extent` texels each, x fastest; transfer-source usage), all in `format`. What the
// kernels correlate is the stored number (DeviceField's FieldFormat: the float, the float16, or a
// unorm's c / (2^b - 1)), and the reference series must be given in the same numbers. Pearson,
// Spearman, Kendall and binned MI are unchanged by an increasing affine value mapping (up to
// rounding); Kraskov MI's max-norm distances are not, so for it the field is that of the stored
// numbers.
struct DeviceEnsemble {
  const Buffer* buffer = nullptr;
  uint64_t voxels = 0;  // of a buffer's members; images: extent's product
  std::span<const CommandBatch::HostImage> images;
  VkExtent3D extent{0, 0, 0};
  FieldFormat format = FieldFormat::Float32;
  uint64_t voxel_count() const {
    return buffer ? voxels : uint64_t(extent.width) * extent.height * extent.depth;
  }
};

// Called after each chunk of voxels with (voxels done, voxels in all).
using CorrelationProgress = std::function<void(uint64_t done, uint64_t total)>;

// Builds each pipeline (per measure and member-count class) on first use and keeps it; compute()
// may be called any number of times.
class CorrelationKernel {
 public:
  // `max_workgroup`: plan with workgroups of at most this many invocations (0: the device's own
  // limit, max_workgroup(ctx)), as on a device that allows no more; for tests and comparisons.
  explicit CorrelationKernel(Context& ctx, uint32_t max_workgroup = 0);
  ~CorrelationKernel();
  CorrelationKernel(const CorrelationKernel&) = delete;
  CorrelationKernel& operator=(const CorrelationKernel&) = delete;

  // The field of `params.measure` between `reference` (member_count values) and every voxel's
  // series; voxel_count values. Uploads the ensemble in chunks of voxels whose device memory
  // stays within `max_device_bytes` (0: a default that fits every device), so ensembles larger
  // than device memory work. Throws std::invalid_argument on bad params or sizes (or a budget too
  // small for one voxel), std::runtime_error when the device lacks the workgroup size or shared
  // memory this member count needs (the message names the limit).
  std::vector<float> compute(const EnsembleView& ens, std::span<const float> reference, const CorrelationParams& params,
                             const CorrelationProgress& progress = {}, uint64_t max_device_bytes = 0);

  // Runs compute() once on one voxel of its own for `params` and `member_count`, so that the
  // pipeline is built and the driver has compiled it (lavapipe compiles at the first dispatch, and
  // its compiler holds ~15 MB of host memory on a cold shader cache): a caller that sizes its
  // buffers from the memory left calls this first. Throws as compute() does for bad params and
  // device limits.
  void prepare(const CorrelationParams& params, uint32_t member_count);

  // Records the field of an ensemble already on the device (DeviceEnsemble); `out` gets its
  // voxel count of floats: the same kernels and bits as compute() on the same stored numbers; a
  // reference with NaN fills `out` with NaN. `tables` must hold `ref`'s tables
  // (record_correlation_tables, earlier in the same batch). A buffer within one texel view
  // (maxTexelBufferElements values) is read in place by one dispatch; a larger one, and images
  // (which the kernels' texel fetches cannot read as one member-major series: one descriptor per
  // member, with indices that differ between the invocations of a workgroup, is beyond what
  // Vulkan guarantees), in chunks of voxels, each copied on the device, in its own format, into a
  // member-major chunk and then read: device memory of one chunk, no host copy. The chunk is
  // `chunk_memory` when given (a host's scratch range: the chunks hold as many multiples of 64
  // voxels as fit), else the kernel's own of at most kRecordChunkBytes; at most `max_chunk_voxels`
  // voxels when given (tests). Throws std::invalid_argument when a buffer is too small,
  // std::runtime_error as compute() does for device limits.
  void record(CommandBatch& batch, const DeviceEnsemble& ensemble, const CorrelationReference& ref,
              const CorrelationTables& tables, Buffer& out, uint64_t max_chunk_voxels = 0,
              const Buffer* chunk_memory = nullptr);
  // The device memory record() keeps for its chunks (64 MiB: dispatches of 16 M float values
  // each, far beyond what it takes to fill any device).
  static constexpr uint64_t kRecordChunkBytes = uint64_t(64) << 20;
  // The smallest chunk memory record() accepts for `members` members of `format`: 64 voxels.
  static uint64_t min_chunk_bytes(uint32_t members, FieldFormat format);
  // A buffer of float32 values.
  void record(CommandBatch& batch, const Buffer& ensemble, uint64_t voxels, const CorrelationReference& ref,
              const CorrelationTables& tables, Buffer& out, uint64_t max_chunk_voxels = 0) {
    DeviceEnsemble members;  // named members: an aggregate initializer warns under -Wextra
    members.buffer = &ensemble;
    members.voxels = voxels;
    record(batch, members, ref, tables, out, max_chunk_voxels);
  }
  // record()'s checks of the buffers and sizes alone (std::invalid_argument), for callers that
  // must refuse before they record anything.
  void check_record(const DeviceEnsemble& ensemble, const CorrelationParams& params, uint32_t members,
                    const Buffer& out) const;

  // The largest workgroup a plan asks for: 1024 (lavapipe's, NVIDIA's and AMD's limit), or less
  // where the device allows less. Only the Kraskov measures grow their workgroups that far (to
  // keep each invocation's neighbour searches within llvmpipe's loop limit); every Vulkan device
  // allows at least 128.
  static constexpr uint32_t kMaxWorkgroup = 1024;
  // kMaxWorkgroup within `ctx`'s maxComputeWorkGroupInvocations and maxComputeWorkGroupSize[0]:
  // what compute() and record() plan with, and what the functions below take as
  // `max_workgroup` to describe the plan of one device.
  static uint32_t max_workgroup(const Context& ctx);
  // Which strategy compute() uses for `member_count` (for messages and the benchmark), e.g.
  // "one invocation per voxel" or "one workgroup per voxel, shared-memory sort".
  static std::string strategy(const CorrelationParams& params, uint32_t member_count,
                              uint32_t max_workgroup = kMaxWorkgroup);
  // Invocations per workgroup and workgroup shared memory the kernel needs for `member_count`
  // members (compute() throws std::runtime_error naming the device limit it exceeds).
  static uint32_t workgroup_size(const CorrelationParams& params, uint32_t member_count,
                                 uint32_t max_workgroup = kMaxWorkgroup);
  static uint64_t shared_memory_bytes(const CorrelationParams& params, uint32_t member_count,
                                      uint32_t max_workgroup = kMaxWorkgroup);
  // The largest |compute() - correlation_field_reference()| the float kernels can show where
  // every comparison of member values is exact in float (series of multiples of 2^-10 whose
  // ranges are powers of two, as the tests use): a few roundings of the final float operations
  // for pearson, spearman and kendall (their counts and rank sums are exact integers); for mutual
  // information, the rounding of the float sum of M per-member terms in the kernel's order and of
  // the tabulated logarithms or digamma values; sqrt(2 b) + that for mi-coefficient, b the
  // bound of its MI. Elsewhere a value within float rounding of a bin edge or of another
  // distance may count differently from the double reference.
  static double error_bound(const CorrelationParams& params, uint32_t member_count,
                            uint32_t max_workgroup = kMaxWorkgroup);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tfm
