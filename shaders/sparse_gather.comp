// q = S x over one chunk of voxels: the TF x (N RGBA entries) gathered at each voxel's coordinate,
// (1-w) x_j + w x_{j+1}. Optionally stores q per voxel and/or adds ||q_c||^2 per channel to
// unsigned 32.32 accumulators (deterministic), optionally of q scaled by the CGLS state's p_scale.
// Voxels without data give q = 0.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_SPARSE_PUSH
#include "solver_layout.h"
#include "tf_common.glsl"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_GATHER_SPEC_WRITE_OUT) const bool WRITE_OUT = true;
layout(constant_id = TFM_GATHER_SPEC_ACCUMULATE_NORM) const bool ACCUMULATE_NORM = false;
layout(constant_id = TFM_GATHER_SPEC_NORM_SCALED) const bool NORM_SCALED = false;

layout(std430, binding = TFM_GATHER_BINDING_COORD) readonly buffer Coord { float coord[]; };
layout(std430, binding = TFM_GATHER_BINDING_X) readonly buffer X { vec4 x[]; };
layout(std430, binding = TFM_GATHER_BINDING_OUT) writeonly buffer Out { vec4 q_out[]; };
layout(std430, binding = TFM_GATHER_BINDING_NORM) buffer Norm { uint norm_accum[]; };
layout(std430, binding = TFM_GATHER_BINDING_STATE) readonly buffer State { CglsState state; };

shared uint s_norm[2u * TFM_GATHER_NORM_SLOTS];

void main() {
  if (ACCUMULATE_NORM) FX_SHARED_ZERO(s_norm, TFM_GATHER_NORM_SLOTS)

  // Scaling by a power of two is exact: the norm is exactly that of q, times 1 / p_scale^2.
  const vec4 inv_scale = NORM_SCALED ? 1.0 / state.p_scale : vec4(1.0);
  uvec2 acc[4] = uvec2[4](uvec2(0u), uvec2(0u), uvec2(0u), uvec2(0u));
  const uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  for (uint i = gl_GlobalInvocationID.x; i < pc.voxel_count; i += stride) {
    uint j;
    float w;
    vec4 q = vec4(0.0);
    if (split_coordinate(coord[i], pc.tf_size, j, w)) q = (1.0 - w) * x[j] + w * x[j + 1u];
    if (WRITE_OUT) q_out[i] = q;
    if (ACCUMULATE_NORM) {
      const vec4 qs = q * inv_scale;
      for (uint c = 0u; c < 4u; ++c) fx_add(acc[c], fx_from_float(qs[c] * qs[c]));
    }
  }
  if (ACCUMULATE_NORM) {
    for (uint c = 0u; c < 4u; ++c) FX_ATOMIC_ADD(s_norm, c, acc[c]);
    FX_SHARED_FLUSH(s_norm, TFM_GATHER_NORM_SLOTS, norm_accum)
  }
}
