// Histogram of one field chunk over B equal bins of [lo, hi], with counters for values below,
// above and NaN (layout: histogram_layout.h). The bin is computed in float32 with `precise`, so
// the host mirror (histogram_bin() in kernels/histogram.h) puts every value in the same bin.
//
// Integer counts are exact and their sum does not depend on the order of the adds, so the result
// is the same on every run, device and chunking. Where the counters fit in shared memory each
// workgroup counts privately and adds its non-zero counters to the buffer once (contention on a
// few hot bins stays inside the workgroup); otherwise every voxel adds to the buffer directly.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_HISTOGRAM_PUSH
#include "histogram_layout.h"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_HIST_SPEC_SHARED_WORDS) const uint kSharedWords = 1u;
layout(constant_id = TFM_HIST_SPEC_USE_SHARED) const uint kUseShared = 0u;

layout(std430, binding = TFM_HIST_BINDING_FIELD) readonly buffer Field { float field[]; };
layout(std430, binding = TFM_HIST_BINDING_COUNTS) buffer Counts { uint counts[]; };

shared uint s_counts[kSharedWords];

uint counter_of(float v) {
  if (isnan(v)) return TFM_HIST_NAN(pc.bins);
  precise float t = (v - pc.lo) * pc.scale;
  if (t < 0.0) return TFM_HIST_BELOW;
  if (t > float(pc.bins)) return TFM_HIST_ABOVE(pc.bins);
  return 1u + min(uint(floor(t)), pc.bins - 1u);
}

void main() {
  const uint n_counters = TFM_HIST_COUNTERS(pc.bins);
  const uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  if (kUseShared != 0u) {
    for (uint k = gl_LocalInvocationID.x; k < n_counters; k += gl_WorkGroupSize.x) s_counts[k] = 0u;
    barrier();
    for (uint i = gl_GlobalInvocationID.x; i < pc.voxel_count; i += stride) atomicAdd(s_counts[counter_of(field[i])], 1u);
    barrier();
    for (uint k = gl_LocalInvocationID.x; k < n_counters; k += gl_WorkGroupSize.x)
      if (s_counts[k] != 0u) atomicAdd(counts[k], s_counts[k]);
  } else {
    for (uint i = gl_GlobalInvocationID.x; i < pc.voxel_count; i += stride) atomicAdd(counts[counter_of(field[i])], 1u);
  }
}
