// Voxel loss between the reference colours T_r(F_r) and T_o(F_o): per channel sums of squared
// and absolute differences over one chunk, in deterministic 32.32 fixed point. NaN voxels
// (in either field) are skipped, as the optimizers skip them.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "shared_layout.h"
#include "tf_common.glsl"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;

layout(std430, binding = TFM_LOSS_BINDING_REF_FIELD) readonly buffer RefField { float ref_field[]; };
layout(std430, binding = TFM_LOSS_BINDING_OPT_FIELD) readonly buffer OptField { float opt_field[]; };
layout(std430, binding = TFM_LOSS_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };
layout(std430, binding = TFM_LOSS_BINDING_OPT_TF) readonly buffer OptTf { vec4 opt_tf[]; };
layout(std430, binding = TFM_LOSS_BINDING_ACCUM) buffer Accum { uint accum[]; };

shared uint s_acc[2u * TFM_LOSS_SLOTS];

void main() {
  FX_SHARED_ZERO(s_acc, TFM_LOSS_SLOTS)

  uvec2 acc[TFM_LOSS_SLOTS];
  for (uint k = 0u; k < TFM_LOSS_SLOTS; ++k) acc[k] = uvec2(0u);
  const uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  for (uint i = gl_GlobalInvocationID.x; i < pc.voxel_count; i += stride) {
    uint jr, jo;
    float wr, wo;
    if (!tf_coordinate(ref_field[i], pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr)) continue;
    if (!tf_coordinate(opt_field[i], pc.opt_lo, pc.opt_scale, pc.opt_tf_size, jo, wo)) continue;
    const vec4 b = (1.0 - wr) * ref_tf[jr] + wr * ref_tf[jr + 1u];
    const vec4 v = (1.0 - wo) * opt_tf[jo] + wo * opt_tf[jo + 1u];
    const vec4 d = abs(clamp(v, 0.0, 1.0) - clamp(b, 0.0, 1.0));
    for (uint c = 0u; c < 4u; ++c) {
      fx_add(acc[c], fx_from_float(d[c] * d[c]));
      fx_add(acc[4u + c], fx_from_float(d[c]));
    }
    fx_add(acc[8], uvec2(0u, 1u));  // 1.0 in 32.32
  }
  for (uint k = 0u; k < TFM_LOSS_SLOTS; ++k) FX_ATOMIC_ADD(s_acc, k, acc[k]);
  FX_SHARED_FLUSH(s_acc, TFM_LOSS_SLOTS, accum)
}
