// Prepares the voxel vectors of the matrix-free solvers over one range of a chunk of them: the
// optimized field's TF coordinate per voxel (TFM_NO_DATA where either field has no data) and
// b = T_r(F_r), the reference colour clamped to [0,1] (0 where there is no data), as the initial
// residual of x = 0. Layout as in residual_map.comp: lanes on consecutive quads of voxels
// (quad_segments.glsl), each writing its quad's four coordinates as one vec4; the reference TF is
// read as texels, and so are both fields, one texel of their format per voxel: a chunk of the
// vectors may start anywhere in a field chunk, so each view starts at the device's texel alignment
// below the range, `field_shift` (`opt_field_shift`) texels before it. Invocation 0 does the range's last count % 4 voxels.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#define TFM_WANT_PREPARE_PUSH
#include "solver_layout.h"
#include "tf_common.glsl"
#include "quad_segments.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;

layout(binding = TFM_PREPARE_BINDING_REF_FIELD) uniform samplerBuffer ref_field;
layout(binding = TFM_PREPARE_BINDING_OPT_FIELD) uniform samplerBuffer opt_field;
layout(binding = TFM_PREPARE_BINDING_REF_TF) uniform samplerBuffer ref_tf;
// The coordinate chunk twice: floats for the tail, vec4 quads for the rest.
layout(std430, binding = TFM_PREPARE_BINDING_COORD) writeonly buffer Coord { float coord[]; };
layout(std430, binding = TFM_PREPARE_BINDING_COORD_QUADS) writeonly buffer CoordQuads { vec4 coord_quads[]; };
layout(std430, binding = TFM_PREPARE_BINDING_RGBA) writeonly buffer Rgba { vec4 rgba[]; };
#ifdef TFM_WEIGHTED
// Weighted least squares: row i and b_i times sqrt(weight_i), the scale kept for gather and scatter.
layout(binding = TFM_PREPARE_BINDING_WEIGHTS) uniform samplerBuffer weight_field;
layout(std430, binding = TFM_PREPARE_BINDING_SCALE) writeonly buffer Scale { float scale[]; };
#endif

// Voxel k of the range: its coordinate, and b (written to the RGBA vector).
float take(uint k) {
  uint jr, jo;
  float wr, wo;
  const bool has_ref =
      tf_coordinate(texelFetch(ref_field, int(pc.field_shift + k)).x, pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr);
  const bool has_opt = tf_coordinate(texelFetch(opt_field, int(pc.opt_field_shift + k)).x, pc.opt_lo, pc.opt_scale,
                                     pc.opt_tf_size, jo, wo);
  const bool ok = has_ref && has_opt;
  // Without data j = 0 and w = 0: the values are valid and replaced (no branch).
  const vec4 b = clamp((1.0 - wr) * texelFetch(ref_tf, int(jr)) + wr * texelFetch(ref_tf, int(jr + 1u)), 0.0, 1.0);
#ifdef TFM_WEIGHTED
  const float row_scale = ok ? sqrt(texelFetch(weight_field, int(pc.weight_field_shift + k)).x) : 0.0;
  scale[pc.first_voxel + k] = row_scale;
  rgba[pc.first_voxel + k] = row_scale * b;
#else
  rgba[pc.first_voxel + k] = ok ? b : vec4(0.0);
#endif
  // x = j + w exactly: w = x - floor(x) (or x - (n-2) at the top node) was exact in float.
  precise float x = float(jo) + wo;
  return ok ? x : TFM_NO_DATA;
}

void main() {
  const uint quads = pc.voxel_count / 4u;
  const uint first_quad = pc.first_voxel / 4u;  // first_voxel is a multiple of 4 (a range start)
  TFM_FOR_EACH_QUAD(q, quads) {
    const uint k = 4u * q;
    coord_quads[first_quad + q] = vec4(take(k), take(k + 1u), take(k + 2u), take(k + 3u));
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint k = 4u * quads; k < pc.voxel_count; ++k) coord[pc.first_voxel + k] = take(k);
}
