// s += S^T r over one range of a chunk of voxels: each voxel adds (1-w) r to entry j and w r to
// entry j+1, per channel, into signed 32.32 fixed-point slots, reduced as tf_pair_reduce.glsl
// describes (every term converted on its own and summed as an integer: the same bits for every
// mode, atomic width, chunking, range split and workgroup count). With UPDATE_RESIDUAL it first
// applies the CGLS residual update r -= alpha (S p) and stores r. The TFM_WEIGHTED variant scales
// each row of S by the voxel's scale (sqrt of its weight, written by sparse_prepare). Lanes take consecutive quads of
// voxels in their subgroup's segment, as in assemble_normal_equations.comp; coordinates, r and p
// are read as texels (the coordinates as RGBA32F quads, r one texel per voxel), r is written
// through a storage buffer; invocation 0 does the range's last count % 4 voxels.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#ifdef TFM_INT64
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#endif
#define TFM_WANT_SPARSE_PUSH
#include "solver_layout.h"
#include "tf_common.glsl"
#include "fixed_point_accumulators.glsl"
#include "quad_segments.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_SCATTER_SPEC_MODE) const uint MODE = TFM_REDUCE_RUNS_SHARED;
// Slots of the workgroup-shared accumulators (1 unless MODE is RUNS_SHARED).
layout(constant_id = TFM_SCATTER_SPEC_SHARED_SLOTS) const uint SHARED_SLOTS = 1u;
// TF entries of each lane's private histogram (0 unless MODE is PRIVATE).
layout(constant_id = TFM_SCATTER_SPEC_PRIVATE_BINS) const uint PRIVATE_BINS = 0u;
layout(constant_id = TFM_SCATTER_SPEC_UPDATE_RESIDUAL) const bool UPDATE_RESIDUAL = false;

// The coordinate chunk twice: floats for the tail, RGBA32F quads over the range for the rest.
layout(std430, binding = TFM_SCATTER_BINDING_COORD) readonly buffer Coord { float coord[]; };
layout(binding = TFM_SCATTER_BINDING_COORD_QUADS) uniform samplerBuffer coord_quads;
// The residual chunk: read as one RGBA32F texel per voxel of the range, written as vec4s.
layout(binding = TFM_SCATTER_BINDING_RESIDUAL_TEXELS) uniform samplerBuffer r_in;
layout(std430, binding = TFM_SCATTER_BINDING_RESIDUAL) writeonly buffer Residual { vec4 r[]; };
layout(binding = TFM_SCATTER_BINDING_P) uniform samplerBuffer p;
layout(std430, binding = TFM_SCATTER_BINDING_STATE) readonly buffer State { CglsState state; };
TFM_DECLARE_ACCUMULATORS(TFM_SCATTER_BINDING_ACCUM)
#ifdef TFM_WEIGHTED
layout(std430, binding = TFM_SCATTER_BINDING_SCALE) readonly buffer Scale { float scale[]; };
#define ROW_SCALE(k) scale[pc.first_voxel + (k)]
#else
#define ROW_SCALE(k) 1.0
#endif

#include "tf_pair_reduce.glsl"

vec4 alpha;

// Voxel k of the range.
void take(uint k, float x) {
  uint j;
  float w;
  const bool ok = split_coordinate(x, pc.tf_size, j, w);
  vec4 ri = texelFetch(r_in, int(k));
  const float row_scale = ROW_SCALE(k);
  if (UPDATE_RESIDUAL && ok) {
    ri -= alpha * (row_scale * ((1.0 - w) * texelFetch(p, int(j)) + w * texelFetch(p, int(j + 1u))));
    r[pc.first_voxel + k] = ri;
  }
  // Without data w = 0 and j = 0 (split_coordinate), and the terms must be 0.
  const vec4 rs = ok ? row_scale * ri : vec4(0.0);
  pair_add(ok, j, (1.0 - w) * rs, w * rs);
}

void main() {
  // Iterations recorded after every channel stopped change nothing: skip them (uniform branch).
  if (UPDATE_RESIDUAL && all(equal(state.running, uvec4(0u)))) return;
  const uint n = pc.tf_size;
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_ZERO(TFM_TF_GRADIENT_SLOTS(n))
  alpha = UPDATE_RESIDUAL ? state.alpha : vec4(0.0);
  pair_begin();

  const uint quads = pc.voxel_count / 4u;
  TFM_FOR_EACH_QUAD(q, quads) {
    const vec4 x = texelFetch(coord_quads, int(q));
    take(4u * q, x.x);
    take(4u * q + 1u, x.y);
    take(4u * q + 2u, x.z);
    take(4u * q + 3u, x.w);
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint k = 4u * quads; k < pc.voxel_count; ++k) take(k, coord[pc.first_voxel + k]);
  pair_end(n);

  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_FLUSH(TFM_TF_GRADIENT_SLOTS(n))
}
