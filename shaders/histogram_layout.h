// Interface of shaders/field_histogram.comp, shared by GLSL and kernels/histogram.cpp: bindings,
// specialization ids, the counter layout and the push-constant block (4-byte scalars only, so
// std430 and C++ layouts coincide; the wrapper static_asserts it).
#ifndef TFMATCH_HISTOGRAM_LAYOUT_H
#define TFMATCH_HISTOGRAM_LAYOUT_H

#include "shared_layout.h"

#ifdef __cplusplus
namespace tfm::gpu {
#endif

#define TFM_HIST_BINDING_FIELD 0   // float: one chunk of the field (the range's last count % 4 voxels)
#define TFM_HIST_BINDING_COUNTS 1  // uint: TFM_HIST_COUNTERS(bins) counters, added to
#define TFM_HIST_BINDING_QUADS 2   // the range's voxels as RGBA32F texels

// Specialization: workgroup size (TFM_SPEC_WORKGROUP_X), then these.
#define TFM_HIST_SPEC_SHARED_WORDS 1       // counters kept per workgroup in shared memory (1 otherwise)
#define TFM_HIST_SPEC_MODE 2               // TFM_HIST_MODE_*
#define TFM_HIST_SPEC_PRIVATE_COUNTERS 3   // counters kept per invocation (1 unless private)

// Where the counts are kept until they are added to the buffer's counters.
#define TFM_HIST_MODE_GLOBAL 0u   // nowhere: every voxel adds to the buffer
#define TFM_HIST_MODE_SHARED 1u   // per workgroup in shared memory, added once per workgroup
#define TFM_HIST_MODE_PRIVATE 2u  // per invocation, no atomics; its non-zero counters added once

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
  uint voxel_count;  // voxels in this range of a chunk
  uint first_voxel;  // the range's first voxel in the chunk (a multiple of 4)
  uint bins;         // B
  float lo;          // bin of v: floor((v - lo) * scale), scale = B / (hi - lo)
  float scale;
} TFM_PUSH_INSTANCE(pc);
#endif

#ifdef __cplusplus
}  // namespace tfm::gpu
#endif

#endif  // TFMATCH_HISTOGRAM_LAYOUT_H
