// Voxel loss between the reference colours b = T_r(F_r) and T_o(F_o): per channel sums of squared
// and absolute differences of the clamped colours, and the voxel count, over one range of a chunk,
// in 32.32 fixed point. Voxels without data (NaN or ±Inf in either field) add nothing, as the optimizers
// skip them. With WITH_BEFORE the same pass also sums the loss before optimization — the second
// field shown with the reference TF, mapped onto its entries by before_lo/before_scale — into
// slots 9-17, so `optimize` measures both losses with one read of the fields.
//
// Every term (d^2 and |d|, each in [0, 1]) is converted on its own to the integer
// floor(term 2^32) and summed modulo 2^64, so the totals are the same bits for any order,
// chunking, range split or workgroup count. Layout as in assemble_normal_equations.comp: lanes on
// consecutive quads of voxels (quad_segments.glsl), fields and TFs read as uniform texel buffers
// (lavapipe turns a storage-buffer load with a per-lane index into a loop over the SIMD lanes),
// and no branch per voxel: a voxel without data adds zeros. Each lane sums in registers and adds
// its sums to the workgroup's shared slots once; the workgroup adds its totals to the global
// slots once.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "shared_layout.h"
#include "tf_common.glsl"
#include "fixed_point.glsl"
#include "quad_segments.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_LOSS_SPEC_WITH_BEFORE) const bool WITH_BEFORE = false;

#define TFM_FIELDS_REF TFM_LOSS_BINDING_REF_FIELD
#define TFM_FIELDS_OPT TFM_LOSS_BINDING_OPT_FIELD
#define TFM_FIELDS_REF_QUADS TFM_LOSS_BINDING_REF_QUADS
#define TFM_FIELDS_OPT_QUADS TFM_LOSS_BINDING_OPT_QUADS
#define TFM_FIELDS_SPEC_NX TFM_LOSS_SPEC_IMAGE_NX
#define TFM_FIELDS_SPEC_NY TFM_LOSS_SPEC_IMAGE_NY
#include "voxel_pair_fields.glsl"
layout(binding = TFM_LOSS_BINDING_REF_TF) uniform samplerBuffer ref_tf;
layout(binding = TFM_LOSS_BINDING_OPT_TF) uniform samplerBuffer opt_tf;
layout(std430, binding = TFM_LOSS_BINDING_ACCUM) buffer Accum { uint accum[]; };

const uint SLOTS = WITH_BEFORE ? 2u * TFM_LOSS_SLOTS : TFM_LOSS_SLOTS;
shared uint s_acc[2u * 2u * TFM_LOSS_SLOTS];
uvec2 acc[2u * TFM_LOSS_SLOTS];  // this lane's sums

// Adds the loss of colour v against b (clamped) to the slots from `base`; zeros when !ok.
void add_loss(uint base, vec4 v, vec4 b, bool ok) {
  const vec4 d = ok ? abs(clamp(v, 0.0, 1.0) - b) : vec4(0.0);
  for (uint c = 0u; c < 4u; ++c) {
    fx_add(acc[base + c], fx_from_float(d[c] * d[c]));
    fx_add(acc[base + 4u + c], fx_from_float(d[c]));
  }
  fx_add(acc[base + 8u], uvec2(0u, ok ? 1u : 0u));  // 1.0 in 32.32
}

void take(float ref_value, float opt_value) {
  uint jr, jo;
  float wr, wo;
  const bool ref_ok = tf_coordinate(ref_value, pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr);
  const bool ok = tf_coordinate(opt_value, pc.opt_lo, pc.opt_scale, pc.opt_tf_size, jo, wo) && ref_ok;
  const vec4 b = clamp((1.0 - wr) * texelFetch(ref_tf, int(jr)) + wr * texelFetch(ref_tf, int(jr + 1u)), 0.0, 1.0);
  add_loss(0u, (1.0 - wo) * texelFetch(opt_tf, int(jo)) + wo * texelFetch(opt_tf, int(jo + 1u)), b, ok);
  if (WITH_BEFORE) {
    uint jb;
    float wb;
    tf_coordinate(opt_value, pc.before_lo, pc.before_scale, pc.ref_tf_size, jb, wb);
    add_loss(TFM_LOSS_SLOTS, (1.0 - wb) * texelFetch(ref_tf, int(jb)) + wb * texelFetch(ref_tf, int(jb + 1u)), b, ok);
  }
}

void main() {
  FX_SHARED_ZERO(s_acc, SLOTS)
  for (uint k = 0u; k < SLOTS; ++k) acc[k] = uvec2(0u);

  const uint quads = pc.voxel_count / 4u;
  TFM_FOR_EACH_QUAD(q, quads) {
    const vec4 r = REF_QUAD(q);
    const vec4 o = OPT_QUAD(q);
    take(r.x, o.x);
    take(r.y, o.y);
    take(r.z, o.z);
    take(r.w, o.w);
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint i = pc.first_voxel + 4u * quads; i < pc.first_voxel + pc.voxel_count; ++i)
      take(REF_VOXEL(i), OPT_VOXEL(i));

  for (uint k = 0u; k < SLOTS; ++k) FX_ATOMIC_ADD(s_acc, k, acc[k])  // skips zeros
  FX_SHARED_FLUSH(s_acc, SLOTS, accum)
}
