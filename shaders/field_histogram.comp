// Histogram of one range of a field chunk over B equal bins of [lo, hi], with counters for values
// below, above and NaN (layout: histogram_layout.h). The bin is computed in float32 with
// `precise`, so the host mirror (histogram_counter() in kernels/histogram.h) puts every value in the
// same bin.
//
// Integer counts are exact and their sum does not depend on the order of the adds, so the result
// is the same on every run, device, chunking, range split and MODE. Lanes read consecutive quads
// of voxels as texels (quad_segments.glsl; invocation 0 reads the range's last count % 4 voxels
// as floats), as in assemble_normal_equations.comp, and keep the counts
//   PRIVATE: in their own array, without atomics or branches (CPU devices: lavapipe turns every
//            shared or buffer atomic with a per-lane address into a loop over the SIMD lanes),
//            adding the non-zero counters to the buffer at the end;
//   SHARED:  in the workgroup's shared array, added to the buffer once per workgroup (GPUs:
//            contention on a few hot bins stays inside the workgroup);
//   GLOBAL:  nowhere: every voxel adds to the buffer (counters beyond shared memory).
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#define TFM_WANT_HISTOGRAM_PUSH
#include "histogram_layout.h"
#include "quad_segments.glsl"
#include "tf_common.glsl"  // no_data

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_HIST_SPEC_SHARED_WORDS) const uint kSharedWords = 1u;
layout(constant_id = TFM_HIST_SPEC_MODE) const uint MODE = TFM_HIST_MODE_GLOBAL;
layout(constant_id = TFM_HIST_SPEC_PRIVATE_COUNTERS) const uint kPrivateCounters = 1u;

layout(binding = TFM_HIST_BINDING_FIELD) uniform samplerBuffer field;  // one voxel a texel
layout(std430, binding = TFM_HIST_BINDING_COUNTS) buffer Counts { uint counts[]; };
layout(binding = TFM_HIST_BINDING_QUADS) uniform samplerBuffer quads_in;

shared uint s_counts[kSharedWords];
uint priv[kPrivateCounters];

// Selects rather than branches: a value without data (NaN, ±Inf) goes to the no-data counter, and
// its bin, computed from a meaningless floor, is never chosen.
uint counter_of(float v) {
  precise float t = (v - pc.lo) * pc.scale;
  const uint in_range = 1u + min(uint(max(floor(t), 0.0)), pc.bins - 1u);
  return no_data(v) ? TFM_HIST_NAN(pc.bins)
                  : t < 0.0 ? TFM_HIST_BELOW : t > float(pc.bins) ? TFM_HIST_ABOVE(pc.bins) : in_range;
}

void count(float v) {
  const uint k = counter_of(v);
  if (MODE == TFM_HIST_MODE_PRIVATE) priv[k] += 1u;
  else if (MODE == TFM_HIST_MODE_SHARED) atomicAdd(s_counts[k], 1u);
  else atomicAdd(counts[k], 1u);
}

void main() {
  const uint n_counters = TFM_HIST_COUNTERS(pc.bins);
  if (MODE == TFM_HIST_MODE_PRIVATE)
    for (uint k = 0u; k < kPrivateCounters; ++k) priv[k] = 0u;
  if (MODE == TFM_HIST_MODE_SHARED) {
    for (uint k = gl_LocalInvocationID.x; k < n_counters; k += gl_WorkGroupSize.x) s_counts[k] = 0u;
    barrier();
  }
  const uint quads = pc.voxel_count / 4u;
  TFM_FOR_EACH_QUAD(q, quads) {
    const vec4 v = texelFetch(quads_in, int(q));
    count(v.x), count(v.y), count(v.z), count(v.w);
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint i = pc.first_voxel + 4u * quads; i < pc.first_voxel + pc.voxel_count; ++i) count(texelFetch(field, int(i)).x);
  if (MODE == TFM_HIST_MODE_PRIVATE) {
    for (uint k = 0u; k < n_counters; ++k)
      if (priv[k] != 0u) atomicAdd(counts[k], priv[k]);
  } else if (MODE == TFM_HIST_MODE_SHARED) {
    barrier();
    for (uint k = gl_LocalInvocationID.x; k < n_counters; k += gl_WorkGroupSize.x)
      if (s_counts[k] != 0u) atomicAdd(counts[k], s_counts[k]);
  }
}
