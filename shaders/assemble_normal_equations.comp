// Assembles the tridiagonal M = S^T S, S^T b and b^T b of the voxel least-squares problem
// (DESIGN.md) for one chunk of voxels, adding into 32.32 fixed-point accumulators. b is the
// reference colour T_r(F_r), evaluated here and never stored as a volume. NaN voxels are skipped.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "shared_layout.h"
#include "tf_common.glsl"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
// Words of workgroup-shared accumulators (2 per slot); 2 when accumulating straight to memory.
layout(constant_id = TFM_ASSEMBLE_SPEC_SHARED_WORDS) const uint SHARED_WORDS = 2u;
layout(constant_id = TFM_ASSEMBLE_SPEC_USE_SHARED) const bool USE_SHARED = true;
// Contiguous voxels one invocation accumulates in registers before touching shared memory.
layout(constant_id = TFM_ASSEMBLE_SPEC_RUN) const uint RUN = TFM_ASSEMBLE_RUN;

layout(std430, binding = TFM_ASSEMBLE_BINDING_REF_FIELD) readonly buffer RefField { float ref_field[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_OPT_FIELD) readonly buffer OptField { float opt_field[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_ACCUM) buffer Accum { uint accum[]; };

shared uint s_acc[SHARED_WORDS];

#define ADD(slot, value) FX_ATOMIC_ADD_TO(USE_SHARED, s_acc, accum, (slot), (value))

void main() {
  const uint n = pc.opt_tf_size;
  const uint slots = TFM_ASSEMBLE_SLOTS(n);
  const uint stb = 2u * n - 1u;
  const uint lid = gl_LocalInvocationID.x;
  if (USE_SHARED) FX_SHARED_ZERO(s_acc, slots)

  // Each invocation walks a contiguous run of TFM_ASSEMBLE_RUN voxels and keeps the sums of the
  // current TF bin in registers (exact 32.32 integer adds), touching the shared accumulators only
  // when the bin changes: neighbouring voxels of smooth fields mostly share a bin, so this removes
  // most atomics. Runs of one workgroup are adjacent; workgroups stride over blocks.
  uvec2 btb[4] = uvec2[4](uvec2(0u), uvec2(0u), uvec2(0u), uvec2(0u));
  uvec2 count = uvec2(0u);
  uint cur = 0xFFFFFFFFu;
  uvec2 d0 = uvec2(0u), d1 = uvec2(0u), od = uvec2(0u);
  uvec2 s0[4] = uvec2[4](uvec2(0u), uvec2(0u), uvec2(0u), uvec2(0u));
  uvec2 s1[4] = uvec2[4](uvec2(0u), uvec2(0u), uvec2(0u), uvec2(0u));
  const uint block = gl_WorkGroupSize.x * RUN;
  for (uint base = gl_WorkGroupID.x * block; base < pc.voxel_count; base += gl_NumWorkGroups.x * block) {
    const uint first = base + lid * RUN;
    const uint last = min(first + RUN, pc.voxel_count);
    for (uint i = first; i < last; ++i) {
      uint jr, jo;
      float wr, wo;
      if (!tf_coordinate(ref_field[i], pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr)) continue;
      if (!tf_coordinate(opt_field[i], pc.opt_lo, pc.opt_scale, n, jo, wo)) continue;
      if (jo != cur) {
        if (cur != 0xFFFFFFFFu) {
          ADD(cur, d0);
          ADD(cur + 1u, d1);
          ADD(n + cur, od);
          for (uint c = 0u; c < 4u; ++c) {
            ADD(stb + 4u * cur + c, s0[c]);
            ADD(stb + 4u * (cur + 1u) + c, s1[c]);
          }
        }
        cur = jo;
        d0 = d1 = od = uvec2(0u);
        for (uint c = 0u; c < 4u; ++c) s0[c] = s1[c] = uvec2(0u);
      }
      const vec4 b = clamp((1.0 - wr) * ref_tf[jr] + wr * ref_tf[jr + 1u], 0.0, 1.0);
      const float u = 1.0 - wo;
      fx_add(d0, fx_from_float(u * u));
      fx_add(d1, fx_from_float(wo * wo));
      fx_add(od, fx_from_float(u * wo));
      for (uint c = 0u; c < 4u; ++c) {
        fx_add(s0[c], fx_from_float(u * b[c]));
        fx_add(s1[c], fx_from_float(wo * b[c]));
        fx_add(btb[c], fx_from_float(b[c] * b[c]));
      }
      fx_add(count, uvec2(0u, 1u));  // 1.0 in 32.32
    }
  }
  if (cur != 0xFFFFFFFFu) {
    ADD(cur, d0);
    ADD(cur + 1u, d1);
    ADD(n + cur, od);
    for (uint c = 0u; c < 4u; ++c) {
      ADD(stb + 4u * cur + c, s0[c]);
      ADD(stb + 4u * (cur + 1u) + c, s1[c]);
    }
  }
  for (uint c = 0u; c < 4u; ++c) ADD(6u * n - 1u + c, btb[c]);
  ADD(6u * n + 3u, count);

  if (USE_SHARED) FX_SHARED_FLUSH(s_acc, slots, accum)
}
