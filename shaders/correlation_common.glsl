// What every correlation kernel shares: bindings, the two strategies, reading a voxel's series,
// deterministic workgroup reductions. A kernel defines CORR_REGIONS (shared-memory regions per
// voxel, 0 for none) before including this file.
//
// Why two strategies. Measures that only stream over the members (pearson; mi-binned once its
// histogram is small) need no per-voxel storage. The others sort or search a voxel's series, so
// it must sit in memory an invocation can index: private arrays of M floats would be registers
// at M <= 32 but spill to slow per-thread memory long before M = 1000, and a workgroup has only
// 32 KiB of shared memory (the portable minimum) for all its invocations. So:
// - M <= TFM_CORR_INVOCATION_MAX_MEMBERS: one invocation per voxel, sequential algorithms on a
//   private slice of shared memory (64 invocations x 33 floats per region: 8.4 KiB a region).
//   Sorting 32 values takes one invocation a few hundred steps; no barriers are needed, and
//   neighbouring invocations read neighbouring addresses of the member-major chunk.
// - M > 32: one workgroup per voxel. The series is loaded once into shared memory (M floats per
//   region: 32 KiB hold 3968 members in two regions, 2368 for mi-kraskov's three); the
//   workgroup merge-sorts it cooperatively (merge path: each invocation merges its own tile of
//   every level, O(M log M) work in all) and every invocation handles members q = lid, lid + T,
//   ... of the per-member work. The chunk is voxel-major so a workgroup reads its series at
//   consecutive addresses.
//
// Determinism: integer totals use 32-bit integer atomics (exact, so order does not matter);
// float totals are summed by each invocation in a fixed member order and then over the
// invocations in a fixed order, so every result has the same bits on every run and however the
// voxels are chunked.
#ifndef TFMATCH_CORRELATION_COMMON_GLSL
#define TFMATCH_CORRELATION_COMMON_GLSL

#define TFM_WANT_CORRELATION_PUSH
#include "correlation_layout.h"
#include "tf_common.glsl"  // no_data

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_CORR_SPEC_GROUP_PER_VOXEL) const bool GROUP_PER_VOXEL = false;
layout(constant_id = TFM_CORR_SPEC_REGION_FLOATS) const uint REGION_FLOATS = 1u;
layout(constant_id = TFM_CORR_SPEC_SHARED_FLOATS) const uint SHARED_FLOATS = 1u;
// The series' layout, a constant so the index needs no select per read (measured on lavapipe: a
// select on a push value cost pearson a third of its speed).
layout(constant_id = TFM_CORR_SPEC_MEMBER_MAJOR) const bool MEMBER_MAJOR = true;

// The chunk's series as float texels: a texel fetch is one vector gather on CPU devices, where a
// storage-buffer load with a per-lane index is a loop over the SIMD lanes (lavapipe, pearson, 10
// members x 1.76 M voxels: kernel 4x faster this way), and the texture path on GPUs.
layout(binding = TFM_CORR_BINDING_ENSEMBLE) uniform samplerBuffer ensemble;
layout(std430, binding = TFM_CORR_BINDING_OUT) writeonly buffer Out { float result[]; };
// The reference series as texels too: every invocation reads the same member's value, which a
// storage-buffer load costs lavapipe a loop over the SIMD lanes (pearson there: 1.1-1.9x faster
// this way, measured 2026-11-29); a GPU broadcasts either. At most kMaxCorrelationMembers values,
// within the texel buffer size every device has (65536).
layout(binding = TFM_CORR_BINDING_REF_VALUES) uniform samplerBuffer ref_value_texels;
#define REF_VALUE(m) texelFetch(ref_value_texels, int(m)).x
layout(std430, binding = TFM_CORR_BINDING_REF_ORDER) readonly buffer RefOrder { uint ref_order[]; };
layout(std430, binding = TFM_CORR_BINDING_REF_GROUP) readonly buffer RefGroup { uint ref_group[]; };
layout(std430, binding = TFM_CORR_BINDING_TABLE) readonly buffer Table { float count_table[]; };

#if CORR_REGIONS > 0
// The series storage: region r of the current voxel starts at corr_region(r).
shared float s_work[SHARED_FLOATS];

uint corr_region(uint r) {
  return r * REGION_FLOATS + (GROUP_PER_VOXEL ? 0u : gl_LocalInvocationIndex * TFM_CORR_SLICE_STRIDE);
}
#endif

#define CORR_NAN uintBitsToFloat(0x7fc00000u)
#define CORR_INF uintBitsToFloat(0x7f800000u)

// Member m of voxel v in this chunk.
float series_value(uint v, uint m) {
  return texelFetch(ensemble, int(MEMBER_MAJOR ? m * pc.member_stride + v : v * pc.member_count + m)).x;
}

// The per-member work of a voxel: every member in one invocation, or members lid, lid + T, ...
// of the workgroup in each of its invocations.
#define CORR_FIRST (GROUP_PER_VOXEL ? gl_LocalInvocationIndex : 0u)
#define CORR_STEP (GROUP_PER_VOXEL ? gl_WorkGroupSize.x : 1u)
#define CORR_FOR_EACH(q, count) for (uint q = CORR_FIRST; q < (count); q += CORR_STEP)

// The voxel of this invocation (one invocation per voxel) or of this workgroup (one workgroup per
// voxel); past the chunk's end when >= pc.voxel_count. Dispatches are 2-D when a chunk needs more
// than maxComputeWorkGroupCount[0] groups. No kernel loops over voxels: llvmpipe (lavapipe) ends
// an invocation's loops once all of them together have run 65535 iterations, so one invocation
// must never take on several voxels' work (kernels/correlation.cpp caps M for the same reason).
uint corr_voxel() {
  const uint group = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
  return GROUP_PER_VOXEL ? group : group * gl_WorkGroupSize.x + gl_LocalInvocationIndex;
}

shared vec4 s_reduce[gl_WorkGroupSize.x];
shared uint s_counts[4];

// (sum, min, max, max) of vec4 terms.
vec4 corr_combine(vec4 a, vec4 b) { return vec4(a.x + b.x, min(a.y, b.y), max(a.z, b.z), max(a.w, b.w)); }

// The voxel's total of per-invocation partial results: the value itself for one invocation per
// voxel; otherwise every invocation combines the workgroup's partials in invocation order (a
// fixed order, and two barriers where a tree takes log2(T) + 1: barriers are what a workgroup
// per voxel pays for on lavapipe, whose invocations switch contexts at each).
vec4 corr_total(vec4 v) {
  if (!GROUP_PER_VOXEL) return v;
  // Every invocation has read the previous total before s_reduce is overwritten.
  barrier();
  s_reduce[gl_LocalInvocationIndex] = v;
  // Every partial is written before any is read.
  memoryBarrierShared();
  barrier();
  vec4 total = s_reduce[0];
  for (uint i = 1u; i < gl_WorkGroupSize.x; ++i) total = corr_combine(total, s_reduce[i]);
  return total;
}

// Clears the integer totals of corr_count_total; call before the first barrier of the voxel
// (which then orders the clearing before every add).
void corr_clear_counts() {
  if (GROUP_PER_VOXEL && gl_LocalInvocationIndex == 0u)
    for (uint c = 0u; c < 4u; ++c) s_counts[c] = 0u;
}

// Integer totals over the workgroup (exact 32-bit atomics; counts here stay far below 2^32);
// once per voxel, after corr_clear_counts.
uvec4 corr_count_total(uvec4 v) {
  if (!GROUP_PER_VOXEL) return v;
  for (uint c = 0u; c < 4u; ++c)
    if (v[c] != 0u) atomicAdd(s_counts[c], v[c]);
  // Every add is done before the totals are read.
  memoryBarrierShared();
  barrier();
  return uvec4(s_counts[0], s_counts[1], s_counts[2], s_counts[3]);
}

// NaN, tested on the bits as no_data() is (tf_common.glsl), so no driver setting that assumes
// ordinary floats can drop it: an exponent of all ones and a mantissa that is not zero.
bool corr_is_nan(float y) { return (floatBitsToUint(y) & 0x7fffffffu) > 0x7f800000u; }

// Partial (unused, min, max, has no value) of one value; a value it flags takes no part in min and
// max. corr_stats_term flags NaN (the rank measures order ±Inf as values).
vec4 corr_value_stats(bool no_value, float y) {
  return no_value ? vec4(0.0, CORR_INF, -CORR_INF, 1.0) : vec4(0.0, y, y, 0.0);
}
vec4 corr_stats_term(float y) { return corr_value_stats(corr_is_nan(y), y); }
#define CORR_STATS_EMPTY vec4(0.0, CORR_INF, -CORR_INF, 0.0)
// The same where an infinite member has no value either (needs_finite_members: mi-binned's bins
// over the range, mi-kraskov's neighbour distances; pearson keeps its own flags).
vec4 corr_finite_stats_term(float y) { return corr_value_stats(no_data(y), y); }

// Writes the voxel's result once (by the first invocation of its workgroup).
void corr_write(uint v, float value) {
  if (!GROUP_PER_VOXEL || gl_LocalInvocationIndex == 0u) result[v] = value;
}

// The result of a voxel with a member without a value (`no_value`: NaN, and ±Inf where the measure
// needs finite members), with all members equal (not `varies`), or of a constant reference,
// following kernels/correlation.h: NaN for a member without a value; for a constant series
// `constant_value` (NaN for the correlation coefficients, 0 for mutual information). Returns false
// when the measure must be computed.
bool corr_special_result(uint v, bool no_value, bool varies, float constant_value) {
  if (no_value) {
    corr_write(v, CORR_NAN);
    return true;
  }
  if (!varies || (pc.flags & TFM_CORR_FLAG_REF_CONSTANT) != 0u) {
    corr_write(v, constant_value);
    return true;
  }
  return false;
}

// The same from the series' stats (corr_total's: y min, z max, w NaN flag).
bool corr_special_case(uint v, vec4 stats, float constant_value) {
  return corr_special_result(v, stats.w > 0.0, stats.y != stats.z, constant_value);
}

#endif
