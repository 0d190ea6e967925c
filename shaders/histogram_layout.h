// Interface of shaders/field_histogram.comp, shared by GLSL and kernels/histogram.cpp: bindings,
// specialization ids, the counter layout and the push-constant block (4-byte scalars only, so
// std430 and C++ layouts coincide; the wrapper static_asserts it).
#ifndef TFMATCH_HISTOGRAM_LAYOUT_H
#define TFMATCH_HISTOGRAM_LAYOUT_H

#include "shared_layout.h"

#ifdef __cplusplus
namespace tfm::gpu {
#endif

#define TFM_HIST_BINDING_FIELD 0   // float: one chunk of the field
#define TFM_HIST_BINDING_COUNTS 1  // uint: TFM_HIST_COUNTERS(bins) counters, added to

// Specialization: workgroup size (TFM_SPEC_WORKGROUP_X), then these.
#define TFM_HIST_SPEC_SHARED_WORDS 1  // counters kept per workgroup in shared memory (1 when global)
#define TFM_HIST_SPEC_USE_SHARED 2    // 1: privatize in shared memory, flush once per workgroup

// Counters: [0] values below lo, [1, bins] the bins of [lo, hi] (hi falls into the last), then
// values above hi, then NaN. Each is a uint32: the wrapper submits at most 2^32 - 1 voxels into
// one set of counters and adds them up on the host in 64 bits.
#define TFM_HIST_BELOW 0u
#define TFM_HIST_ABOVE(bins) ((bins) + 1u)
#define TFM_HIST_NAN(bins) ((bins) + 2u)
#define TFM_HIST_COUNTERS(bins) ((bins) + 3u)
#define TFM_HIST_MAX_BINS 65536u

#if defined(__cplusplus) || defined(TFM_WANT_HISTOGRAM_PUSH)
TFM_PUSH_CONSTANTS(HistogramPush) {
  uint voxel_count;  // voxels in this chunk
  uint bins;         // B
  float lo;          // bin of v: floor((v - lo) * scale), scale = B / (hi - lo)
  float scale;
} TFM_PUSH_INSTANCE(pc);
#endif

#ifdef __cplusplus
}  // namespace tfm::gpu
#endif

#endif  // TFMATCH_HISTOGRAM_LAYOUT_H
