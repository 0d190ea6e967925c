// Pipeline and dispatches of the field-histogram kernel.
#include "tfmatch/kernels/histogram.h"

#include <algorithm>
#include <limits>
#include <stdexcept>

#include "tfmatch/engine/commands.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/shaders/shader_registry.h"

namespace tfm {

static_assert(sizeof(gpu::HistogramPush) == 20, "HistogramPush must match the GLSL std430 block");

namespace {
constexpr auto kBindingCounts =
    gpu::binding_counts({TFM_HIST_BINDING_FIELD, TFM_HIST_BINDING_COUNTS, TFM_HIST_BINDING_QUADS});
// lavapipe stops a shader after 65535 iterations of a loop: a lane takes at most 32768 quads.
constexpr uint64_t kMaxLaneQuads = 32768;
}  // namespace

FieldHistogramKernel::FieldHistogramKernel(Context& ctx, uint32_t bins, HistogramMode mode) : ctx_(ctx), bins_(bins) {
  if (bins < 1 || bins > TFM_HIST_MAX_BINS)
    throw std::invalid_argument("histogram: " + std::to_string(bins) + " bins (need 1 to " +
                                std::to_string(TFM_HIST_MAX_BINS) + ")");
  const uint32_t counters = TFM_HIST_COUNTERS(bins);
  const bool fits_shared = uint64_t(counters) * sizeof(uint32_t) <= ctx.limits().maxComputeSharedMemorySize;
  const bool fits_private = counters <= private_limit(ctx, kPrivateHistogramCounters);
  if (mode == HistogramMode::Auto)
    mode = is_cpu_device(ctx) && fits_private ? HistogramMode::Private
           : fits_shared                      ? HistogramMode::Shared
                                              : HistogramMode::Global;
  if ((mode == HistogramMode::Shared && !fits_shared) || (mode == HistogramMode::Private && !fits_private))
    throw std::invalid_argument("histogram: " + std::to_string(counters) + " counters do not fit the device's " +
                                (mode == HistogramMode::Shared ? "shared memory" : "private budget"));
  mode_ = mode;
  const bool priv = mode == HistogramMode::Private;
  workgroup_size_ = priv ? lane_workgroup_size(ctx, 0, "field_histogram") : TFM_VOXEL_WORKGROUP;
  // Private lanes flush their counters once: lanes cover 16 times as many quads where the range
  // has them, and never fewer voxels than counters when the range is spread over more groups.
  lane_voxels_ = 4 * std::min<uint64_t>(kMaxLaneQuads, 16 * uint64_t(counters));
  const uint32_t shader_mode = priv ? TFM_HIST_MODE_PRIVATE : mode == HistogramMode::Shared ? TFM_HIST_MODE_SHARED
                                                                                           : TFM_HIST_MODE_GLOBAL;
  PipelineDesc desc;
  desc.shader = "field_histogram";
  desc.binding_counts = gpu::to_vector(kBindingCounts);
  desc.binding_kinds = texel_binding_kinds(desc.binding_counts.size(), {TFM_HIST_BINDING_QUADS, TFM_HIST_BINDING_FIELD});
  desc.push_constant_bytes = sizeof(gpu::HistogramPush);
  desc.workgroup_size = workgroup_size_;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, workgroup_size_},
                                    {TFM_HIST_SPEC_SHARED_WORDS, mode == HistogramMode::Shared ? counters : 1u},
                                    {TFM_HIST_SPEC_MODE, shader_mode},
                                    {TFM_HIST_SPEC_PRIVATE_COUNTERS, priv ? counters : 1u}});
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = shared_pipeline(ctx, desc);
}

FieldHistogram FieldHistogramKernel::run(const DeviceField& field, double lo, double hi) const {
  if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi) || !std::isfinite(histogram_scale(lo, hi, bins_)))
    throw std::invalid_argument("histogram: range [" + std::to_string(lo) + ", " + std::to_string(hi) +
                                "] is not finite and increasing");
  const uint32_t n_counters = TFM_HIST_COUNTERS(bins_);
  Buffer counts(ctx_, uint64_t(n_counters) * sizeof(uint32_t), MemoryUsage::Device, "histogram counters");
  std::vector<uint64_t> total(n_counters, 0);
  std::vector<uint32_t> words(n_counters);
  gpu::HistogramPush push{};
  push.bins = bins_;
  push.lo = float(lo);
  push.scale = histogram_scale(lo, hi, bins_);
  // uint32 counters: one batch counts at most 2^32 - 1 voxels before they are read and summed.
  const std::vector<QuadRange> ranges = quad_ranges(field, texel_range_quads(ctx_, 0, "field_histogram"));
  size_t i = 0;
  while (i < ranges.size()) {
    CommandBatch batch(ctx_);
    batch.fill(counts, 0u);
    batch.barrier();
    uint64_t in_batch = 0;
    for (; i < ranges.size() && in_batch + ranges[i].voxels <= std::numeric_limits<uint32_t>::max(); ++i) {
      const QuadRange& r = ranges[i];
      push.voxel_count = uint32_t(r.voxels);
      push.first_voxel = uint32_t(r.first);
      batch.dispatch(*pipeline_,
                     {voxel_texels(field, r.chunk), counts, quad_texels(field, r)},
                     push, {lane_groups(ctx_, workgroup_size_, r.voxels, lane_voxels_, TFM_HIST_COUNTERS(bins_))});
      batch.barrier();
      in_batch += r.voxels;
    }
    batch.submit_and_wait();
    readback(ctx_, counts, words.data(), words.size() * sizeof(uint32_t));
    for (uint32_t k = 0; k < n_counters; ++k) total[k] += words[k];
  }
  FieldHistogram h;
  h.lo = lo;
  h.hi = hi;
  h.below = total[TFM_HIST_BELOW];
  h.above = total[TFM_HIST_ABOVE(bins_)];
  h.nan = total[TFM_HIST_NAN(bins_)];
  h.bins.assign(total.begin() + 1, total.begin() + 1 + bins_);
  return h;
}

}  // namespace tfm
