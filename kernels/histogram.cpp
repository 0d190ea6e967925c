// Pipeline and dispatches of the field-histogram kernel.
#include "histogram.h"

#include <algorithm>
#include <limits>
#include <stdexcept>

#include "commands.h"
#include "context.h"
#include "shader_registry.h"
#include "voxel_pair.h"

namespace tfm {

static_assert(sizeof(gpu::HistogramPush) == 16, "HistogramPush must match the GLSL std430 block");

namespace {
constexpr auto kBindingCounts = gpu::binding_counts({TFM_HIST_BINDING_FIELD, TFM_HIST_BINDING_COUNTS});
}  // namespace

uint64_t FieldHistogram::finite() const {
  uint64_t n = below + above;
  for (uint64_t c : bins) n += c;
  return n;
}

FieldHistogramKernel::FieldHistogramKernel(Context& ctx, uint32_t bins, bool force_global) : ctx_(ctx), bins_(bins) {
  if (bins < 1 || bins > TFM_HIST_MAX_BINS)
    throw std::invalid_argument("histogram: " + std::to_string(bins) + " bins (need 1 to " +
                                std::to_string(TFM_HIST_MAX_BINS) + ")");
  const uint64_t shared_bytes = uint64_t(TFM_HIST_COUNTERS(bins)) * sizeof(uint32_t);
  use_shared_ = !force_global && shared_bytes <= ctx.limits().maxComputeSharedMemorySize;
  PipelineDesc desc;
  desc.shader = "field_histogram";
  desc.binding_counts = gpu::to_vector(kBindingCounts);
  desc.push_constant_bytes = sizeof(gpu::HistogramPush);
  desc.workgroup_size = TFM_VOXEL_WORKGROUP;
  desc.specialization = gpu::by_id({{TFM_SPEC_WORKGROUP_X, TFM_VOXEL_WORKGROUP},
                                    {TFM_HIST_SPEC_SHARED_WORDS, use_shared_ ? TFM_HIST_COUNTERS(bins) : 1u},
                                    {TFM_HIST_SPEC_USE_SHARED, use_shared_ ? 1u : 0u}});
  desc.spirv = shader_spirv(desc.shader);
  pipeline_ = std::make_unique<ComputePipeline>(ctx, desc);
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
  size_t c = 0;
  while (c < field.chunk_count()) {
    CommandBatch batch(ctx_);
    batch.fill(counts, 0u);
    batch.barrier();
    uint64_t in_batch = 0;
    for (; c < field.chunk_count() && in_batch + field.chunk_size(c) <= std::numeric_limits<uint32_t>::max(); ++c) {
      push.voxel_count = uint32_t(field.chunk_size(c));
      batch.dispatch(*pipeline_, {field.chunk(c), counts}, push, {voxel_groups(ctx_, field.chunk_size(c))});
      batch.barrier();
      in_batch += field.chunk_size(c);
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
