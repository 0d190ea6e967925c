// Residual map of DESIGN.md over one chunk of voxels: || premul(T_r(F_r)) - premul(T_o(F_o)) ||_2
// over RGBA, premul(r, g, b, a) = (a r, a g, a b, a); 0 where either field has no data (NaN).
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "render_layout.h"
#include "tf_common.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;

layout(std430, binding = TFM_RESIDUAL_BINDING_REF_FIELD) readonly buffer RefField { float ref_field[]; };
layout(std430, binding = TFM_RESIDUAL_BINDING_OPT_FIELD) readonly buffer OptField { float opt_field[]; };
layout(std430, binding = TFM_RESIDUAL_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };
layout(std430, binding = TFM_RESIDUAL_BINDING_OPT_TF) readonly buffer OptTf { vec4 opt_tf[]; };
layout(std430, binding = TFM_RESIDUAL_BINDING_OUT) writeonly buffer Residual { float residual[]; };

// `precise` keeps each product rounded on its own: a compiler that fused one side's products into
// the subtraction (fma(b.rgb, b.a, -v.rgb * v.a)) would give a field against itself a residual of
// one rounding instead of 0 (seen on NVIDIA's driver 580: 2.5e-8).
vec4 premultiplied(vec4 c) {
  precise vec3 rgb = c.rgb * c.a;
  return vec4(rgb, c.a);
}

void main() {
  const uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  for (uint i = gl_GlobalInvocationID.x; i < pc.voxel_count; i += stride) {
    uint jr, jo;
    float wr, wo;
    const bool ref_ok = tf_coordinate(ref_field[i], pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr);
    const bool opt_ok = tf_coordinate(opt_field[i], pc.opt_lo, pc.opt_scale, pc.opt_tf_size, jo, wo);
    if (!ref_ok || !opt_ok) {
      residual[i] = 0.0;
      continue;
    }
    // Clamped to [0, 1] as the voxel loss and the renderer do, so all three see the same colours.
    precise vec4 b = clamp((1.0 - wr) * ref_tf[jr] + wr * ref_tf[jr + 1u], 0.0, 1.0);
    precise vec4 v = clamp((1.0 - wo) * opt_tf[jo] + wo * opt_tf[jo + 1u], 0.0, 1.0);
    precise vec4 d = premultiplied(b) - premultiplied(v);
    residual[i] = length(d);
  }
}
