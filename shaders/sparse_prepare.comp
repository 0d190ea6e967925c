// Prepares the voxel vectors of the matrix-free solvers for one chunk: the optimized field's TF
// coordinate per voxel (TFM_NO_DATA where either field has no data) and b = T_r(F_r), the
// reference colour clamped to [0,1] (0 where there is no data), as the initial residual of x = 0.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_PREPARE_PUSH
#include "solver_layout.h"
#include "tf_common.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;

layout(std430, binding = TFM_PREPARE_BINDING_REF_FIELD) readonly buffer RefField { float ref_field[]; };
layout(std430, binding = TFM_PREPARE_BINDING_OPT_FIELD) readonly buffer OptField { float opt_field[]; };
layout(std430, binding = TFM_PREPARE_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };
layout(std430, binding = TFM_PREPARE_BINDING_COORD) writeonly buffer Coord { float coord[]; };
layout(std430, binding = TFM_PREPARE_BINDING_RGBA) writeonly buffer Rgba { vec4 rgba[]; };

void main() {
  const uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  for (uint i = gl_GlobalInvocationID.x; i < pc.voxel_count; i += stride) {
    const uint f = pc.field_offset + i;
    uint jr, jo;
    float wr, wo;
    const bool has_ref = tf_coordinate(ref_field[f], pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr);
    const bool has_opt = tf_coordinate(opt_field[f], pc.opt_lo, pc.opt_scale, pc.opt_tf_size, jo, wo);
    if (!has_ref || !has_opt) {
      coord[i] = TFM_NO_DATA;
      rgba[i] = vec4(0.0);
      continue;
    }
    // x = j + w exactly: w = x - floor(x) (or x - (n-2) at the top node) was exact in float.
    precise float x = float(jo) + wo;
    coord[i] = x;
    rgba[i] = clamp((1.0 - wr) * ref_tf[jr] + wr * ref_tf[jr + 1u], 0.0, 1.0);
  }
}
