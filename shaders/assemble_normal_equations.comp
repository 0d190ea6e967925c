// Assembles the tridiagonal M = S^T S, S^T b and b^T b of the voxel least-squares problem
// (DESIGN.md) for one chunk of voxels, adding into 32.32 fixed-point accumulators. b is the
// reference colour T_r(F_r), evaluated here and never stored as a volume. NaN voxels are skipped.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "shared_layout.h"
#include "tf_common.glsl"

layout(local_size_x_id = 0) in;
// Words of workgroup-shared accumulators (2 per slot); 2 when accumulating straight to memory.
layout(constant_id = 1) const uint SHARED_WORDS = 2u;
layout(constant_id = 2) const bool USE_SHARED = true;

layout(std430, binding = TFM_ASSEMBLE_BINDING_REF_FIELD) readonly buffer RefField { float ref_field[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_OPT_FIELD) readonly buffer OptField { float opt_field[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_ACCUM) buffer Accum { uint accum[]; };

shared uint s_acc[SHARED_WORDS];

#define ADD(slot, value)                      \
  if (USE_SHARED) {                           \
    FX_ATOMIC_ADD(s_acc, (slot), (value))     \
  } else {                                    \
    FX_ATOMIC_ADD(accum, (slot), (value))     \
  }

void main() {
  const uint n = pc.opt_tf_size;
  const uint slots = TFM_ASSEMBLE_SLOTS(n);
  const uint stb = 2u * n - 1u;
  const uint lid = gl_LocalInvocationID.x;
  if (USE_SHARED) {
    for (uint k = lid; k < 2u * slots; k += gl_WorkGroupSize.x) s_acc[k] = 0u;
  }
  // The zeroed shared accumulators are visible before any invocation adds to them.
  memoryBarrierShared();
  barrier();

  uvec2 btb[4] = uvec2[4](uvec2(0u), uvec2(0u), uvec2(0u), uvec2(0u));
  uvec2 count = uvec2(0u);
  const uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
  for (uint i = gl_GlobalInvocationID.x; i < pc.voxel_count; i += stride) {
    uint jr, jo;
    float wr, wo;
    if (!tf_coordinate(ref_field[i], pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr)) continue;
    if (!tf_coordinate(opt_field[i], pc.opt_lo, pc.opt_scale, n, jo, wo)) continue;
    const vec4 b = (1.0 - wr) * ref_tf[jr] + wr * ref_tf[jr + 1u];
    const float u = 1.0 - wo;
    ADD(jo, fx_from_float(u * u));
    ADD(jo + 1u, fx_from_float(wo * wo));
    ADD(n + jo, fx_from_float(u * wo));
    for (uint c = 0u; c < 4u; ++c) {
      const float bc = clamp(b[c], 0.0, 1.0);
      ADD(stb + 4u * jo + c, fx_from_float(u * bc));
      ADD(stb + 4u * (jo + 1u) + c, fx_from_float(wo * bc));
      fx_add(btb[c], fx_from_float(bc * bc));
    }
    fx_add(count, uvec2(0u, 1u));  // 1.0 in 32.32
  }
  for (uint c = 0u; c < 4u; ++c) ADD(6u * n - 1u + c, btb[c]);
  ADD(6u * n + 3u, count);

  if (USE_SHARED) {
    // Every shared add of this workgroup is complete before the totals are flushed.
    memoryBarrierShared();
    barrier();
    for (uint k = lid; k < slots; k += gl_WorkGroupSize.x) {
      FX_ATOMIC_ADD(accum, k, uvec2(s_acc[2u * k], s_acc[2u * k + 1u]));
    }
  }
}
