// q = S x over one range of a chunk of voxels: the TF x (N RGBA entries) gathered at each voxel's
// coordinate, (1-w) x_j + w x_{j+1}. Optionally stores q per voxel and/or adds ||q_c||^2 per
// channel to unsigned 32.32 accumulators (every term converted on its own and summed as an
// integer: the same bits for every workgroup size, range split and chunking), optionally of q
// scaled by the CGLS state's p_scale; then it does nothing once every CGLS channel has stopped.
// Voxels without data give q = 0. The TFM_WEIGHTED variant scales each row by the voxel's scale
// (sqrt of its weight, written by sparse_prepare). Layout as in residual_map.comp: lanes on consecutive quads of
// coordinates (quad_segments.glsl) read as texels, x read as texels (lavapipe turns a storage
// load with a per-lane index into a loop over the SIMD lanes), each lane's sums in registers,
// added to the workgroup's and then the global slots once; invocation 0 does the range's last
// count % 4 voxels.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#define TFM_WANT_SPARSE_PUSH
#include "solver_layout.h"
#include "tf_common.glsl"
#include "fixed_point.glsl"
#include "quad_segments.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_GATHER_SPEC_WRITE_OUT) const bool WRITE_OUT = true;
layout(constant_id = TFM_GATHER_SPEC_ACCUMULATE_NORM) const bool ACCUMULATE_NORM = false;
layout(constant_id = TFM_GATHER_SPEC_NORM_SCALED) const bool NORM_SCALED = false;

// The coordinate chunk twice: floats for the tail, RGBA32F quads over the range for the rest.
layout(std430, binding = TFM_GATHER_BINDING_COORD) readonly buffer Coord { float coord[]; };
layout(binding = TFM_GATHER_BINDING_COORD_QUADS) uniform samplerBuffer coord_quads;
layout(binding = TFM_GATHER_BINDING_X) uniform samplerBuffer x;
layout(std430, binding = TFM_GATHER_BINDING_OUT) writeonly buffer Out { vec4 q_out[]; };
layout(std430, binding = TFM_GATHER_BINDING_NORM) buffer Norm { uint norm_accum[]; };
layout(std430, binding = TFM_GATHER_BINDING_STATE) readonly buffer State { CglsState state; };
#ifdef TFM_WEIGHTED
layout(std430, binding = TFM_GATHER_BINDING_SCALE) readonly buffer Scale { float scale[]; };
#define ROW_SCALE(i) scale[i]
#else
#define ROW_SCALE(i) 1.0
#endif

shared uint s_norm[2u * TFM_GATHER_NORM_SLOTS];

vec4 inv_scale;
uvec2 acc[4];

void take(uint i, float c) {
  uint j;
  float w;
  // Without data j = 0 and w = 0 (split_coordinate): the product is replaced by 0, no branch.
  const bool ok = split_coordinate(c, pc.tf_size, j, w);
  const vec4 q = ok ? ROW_SCALE(i) * ((1.0 - w) * texelFetch(x, int(j)) + w * texelFetch(x, int(j + 1u))) : vec4(0.0);
  if (WRITE_OUT) q_out[i] = q;
  if (ACCUMULATE_NORM) {
    const vec4 qs = q * inv_scale;
    for (uint k = 0u; k < 4u; ++k) fx_add(acc[k], fx_from_float(qs[k] * qs[k]));
  }
}

void main() {
  // Gathers recorded after every channel stopped change nothing: skip them (uniform branch).
  if (NORM_SCALED && all(equal(state.running, uvec4(0u)))) return;
  if (ACCUMULATE_NORM) FX_SHARED_ZERO(s_norm, TFM_GATHER_NORM_SLOTS)

  // Scaling by a power of two is exact: the norm is exactly that of q, times 1 / p_scale^2.
  inv_scale = NORM_SCALED ? 1.0 / state.p_scale : vec4(1.0);
  for (uint k = 0u; k < 4u; ++k) acc[k] = uvec2(0u);
  const uint quads = pc.voxel_count / 4u;
  TFM_FOR_EACH_QUAD(q, quads) {
    const vec4 c = texelFetch(coord_quads, int(q));
    const uint i = pc.first_voxel + 4u * q;
    take(i, c.x);
    take(i + 1u, c.y);
    take(i + 2u, c.z);
    take(i + 3u, c.w);
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint i = pc.first_voxel + 4u * quads; i < pc.first_voxel + pc.voxel_count; ++i) take(i, coord[i]);
  if (ACCUMULATE_NORM) {
    for (uint k = 0u; k < 4u; ++k) FX_ATOMIC_ADD(s_norm, k, acc[k]);
    FX_SHARED_FLUSH(s_norm, TFM_GATHER_NORM_SLOTS, norm_accum)
  }
}
