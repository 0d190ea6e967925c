// Residual map of DESIGN.md over one range of a chunk's voxels: || premul(T_r(F_r)) -
// premul(T_o(F_o)) ||_2 over RGBA, premul(r, g, b, a) = (a r, a g, a b, a); 0 where either field
// has no data (NaN, ±Inf: no_data() in tf_common.glsl). Layout as in
// assemble_normal_equations.comp: lanes on consecutive quads of voxels (quad_segments.glsl), fields
// and TFs read as uniform texel buffers (lavapipe turns a storage-buffer load with a per-lane index
// into a loop over the SIMD lanes), each lane writing its quad's four residuals as one vec4;
// invocation 0 does the range's last count % 4 voxels.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "render_layout.h"
#include "tf_common.glsl"
#include "quad_segments.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;

#define TFM_FIELDS_REF TFM_RESIDUAL_BINDING_REF_FIELD
#define TFM_FIELDS_OPT TFM_RESIDUAL_BINDING_OPT_FIELD
#define TFM_FIELDS_REF_QUADS TFM_RESIDUAL_BINDING_REF_QUADS
#define TFM_FIELDS_OPT_QUADS TFM_RESIDUAL_BINDING_OPT_QUADS
#define TFM_FIELDS_SPEC_NX TFM_RESIDUAL_SPEC_IMAGE_NX
#define TFM_FIELDS_SPEC_NY TFM_RESIDUAL_SPEC_IMAGE_NY
#include "voxel_pair_fields.glsl"
layout(binding = TFM_RESIDUAL_BINDING_REF_TF) uniform samplerBuffer ref_tf;
layout(binding = TFM_RESIDUAL_BINDING_OPT_TF) uniform samplerBuffer opt_tf;
// The output chunk twice: floats for the tail, quads (from first_voxel / 4) for the rest.
layout(std430, binding = TFM_RESIDUAL_BINDING_OUT) writeonly buffer Residual { float residual[]; };
layout(std430, binding = TFM_RESIDUAL_BINDING_OUT_QUADS) writeonly buffer ResidualQuads { vec4 residual_quads[]; };

// `precise` keeps each product rounded on its own: a compiler that fused one side's products into
// the subtraction (fma(b.rgb, b.a, -v.rgb * v.a)) would give a field against itself a residual of
// one rounding instead of 0 (seen on NVIDIA's driver 580: 2.5e-8).
vec4 premultiplied(vec4 c) {
  precise vec3 rgb = c.rgb * c.a;
  return vec4(rgb, c.a);
}

float residual_of(float ref_value, float opt_value) {
  uint jr, jo;
  float wr, wo;
  const bool ref_ok = tf_coordinate(ref_value, pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr);
  const bool opt_ok = tf_coordinate(opt_value, pc.opt_lo, pc.opt_scale, pc.opt_tf_size, jo, wo);
  // Clamped to [0, 1] as the voxel loss and the renderer do, so all three see the same colours.
  // Without data j = 0 and w = 0: the colours are valid, the result is replaced by 0 (no branch).
  precise vec4 b = clamp((1.0 - wr) * texelFetch(ref_tf, int(jr)) + wr * texelFetch(ref_tf, int(jr + 1u)), 0.0, 1.0);
  precise vec4 v = clamp((1.0 - wo) * texelFetch(opt_tf, int(jo)) + wo * texelFetch(opt_tf, int(jo + 1u)), 0.0, 1.0);
  precise vec4 d = premultiplied(b) - premultiplied(v);
  return ref_ok && opt_ok ? length(d) : 0.0;
}

void main() {
  const uint quads = pc.voxel_count / 4u;
  const uint first_quad = pc.first_voxel / 4u;  // first_voxel is a multiple of 4 (a range start)
  TFM_FOR_EACH_QUAD(q, quads) {
    const vec4 r = REF_QUAD(q);
    const vec4 o = OPT_QUAD(q);
    residual_quads[first_quad + q] =
        vec4(residual_of(r.x, o.x), residual_of(r.y, o.y), residual_of(r.z, o.z), residual_of(r.w, o.w));
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint i = pc.first_voxel + 4u * quads; i < pc.first_voxel + pc.voxel_count; ++i)
      residual[i] = residual_of(REF_VOXEL(i), OPT_VOXEL(i));
}
