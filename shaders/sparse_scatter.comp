// s += S^T r over one chunk of voxels: each voxel adds (1-w) r to entry j and w r to entry j+1,
// per channel, into signed 32.32 fixed-point slots (deterministic whatever the scheduling).
// With UPDATE_RESIDUAL it first applies the CGLS residual update r -= alpha (S p) and stores r.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_SPARSE_PUSH
#include "solver_layout.h"
#include "tf_common.glsl"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
// Words of workgroup-shared accumulators (2 per slot); 2 when adding straight to memory.
layout(constant_id = TFM_SCATTER_SPEC_SHARED_WORDS) const uint SHARED_WORDS = 2u;
layout(constant_id = TFM_SCATTER_SPEC_USE_SHARED) const bool USE_SHARED = true;
layout(constant_id = TFM_SCATTER_SPEC_UPDATE_RESIDUAL) const bool UPDATE_RESIDUAL = false;

layout(std430, binding = TFM_SCATTER_BINDING_COORD) readonly buffer Coord { float coord[]; };
layout(std430, binding = TFM_SCATTER_BINDING_RESIDUAL) buffer Residual { vec4 r[]; };
layout(std430, binding = TFM_SCATTER_BINDING_P) readonly buffer P { vec4 p[]; };
layout(std430, binding = TFM_SCATTER_BINDING_STATE) readonly buffer State { CglsState state; };
layout(std430, binding = TFM_SCATTER_BINDING_ACCUM) buffer Accum { uint accum[]; };

shared uint s_acc[SHARED_WORDS];

// Float sums of the current bin over the voxels of one run (at most TFM_SOLVER_RUN terms):
// entry j (lo) and j+1 (hi). Which voxels form a run is fixed by their indices, so the sums (and
// the fixed-point totals) are the same on every run; converting once per bin and run instead of
// once per term is what makes the kernel fast.
vec4 lo_sum, hi_sum;

void flush_bin(uint j) {
  FX_ADD_TF_PAIR(USE_SHARED, s_acc, accum, j, lo_sum, hi_sum)
  lo_sum = hi_sum = vec4(0.0);
}

void main() {
  // Iterations recorded after every channel stopped change nothing: skip them (uniform branch).
  if (UPDATE_RESIDUAL && all(equal(state.running, uvec4(0u)))) return;
  const uint n = pc.tf_size;
  const uint lid = gl_LocalInvocationID.x;
  if (USE_SHARED) FX_SHARED_ZERO(s_acc, TFM_TF_GRADIENT_SLOTS(n))

  vec4 alpha = vec4(0.0);
  if (UPDATE_RESIDUAL) alpha = state.alpha;
  lo_sum = hi_sum = vec4(0.0);
  uint cur = 0xFFFFFFFFu;
  // Each invocation walks a contiguous run; runs of one workgroup are adjacent, workgroups
  // stride over blocks.
  const uint block = gl_WorkGroupSize.x * TFM_SOLVER_RUN;
  for (uint base = gl_WorkGroupID.x * block; base < pc.voxel_count; base += gl_NumWorkGroups.x * block) {
    const uint first = base + lid * TFM_SOLVER_RUN;
    const uint last = min(first + TFM_SOLVER_RUN, pc.voxel_count);
    for (uint i = first; i < last; ++i) {
      uint j;
      float w;
      if (!split_coordinate(coord[i], n, j, w)) continue;
      vec4 ri = r[i];
      if (UPDATE_RESIDUAL) {
        ri -= alpha * ((1.0 - w) * p[j] + w * p[j + 1u]);
        r[i] = ri;
      }
      if (j != cur) {
        if (cur != 0xFFFFFFFFu) flush_bin(cur);
        cur = j;
      }
      lo_sum += (1.0 - w) * ri;
      hi_sum += w * ri;
    }
    // Sums never span runs: a run is the aligned index range [16k, 16k+16), so they do not
    // depend on the number of workgroups either.
    if (cur != 0xFFFFFFFFu) flush_bin(cur);
    cur = 0xFFFFFFFFu;
  }

  if (USE_SHARED) FX_SHARED_FLUSH(s_acc, TFM_TF_GRADIENT_SLOTS(n), accum)
}
