// Loss and gradient of the voxel objective for gradient descent, over one chunk of voxels: per
// voxel e = T_o(F_o) - b with T_o = x (unclamped, the iterate is kept in [0,1]), b = T_r(F_r)
// clamped to [0,1]; l2 adds e^2 to the loss and (1-w) e, w e to entries j, j+1 of the gradient
// sum; l1 adds |e| and (1-w) sign(e), w sign(e). Deterministic signed 32.32 fixed-point sums.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "solver_layout.h"
#include "tf_common.glsl"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
// Words of workgroup-shared gradient accumulators (2 per slot); 2 when adding straight to memory.
layout(constant_id = TFM_GD_SPEC_SHARED_WORDS) const uint SHARED_WORDS = 2u;
layout(constant_id = TFM_GD_SPEC_USE_SHARED) const bool USE_SHARED = true;
layout(constant_id = TFM_GD_SPEC_LOSS_L1) const bool LOSS_L1 = false;

layout(std430, binding = TFM_GD_BINDING_REF_FIELD) readonly buffer RefField { float ref_field[]; };
layout(std430, binding = TFM_GD_BINDING_OPT_FIELD) readonly buffer OptField { float opt_field[]; };
layout(std430, binding = TFM_GD_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };
layout(std430, binding = TFM_GD_BINDING_X) readonly buffer X { vec4 x[]; };
layout(std430, binding = TFM_GD_BINDING_ACCUM) buffer Accum { uint accum[]; };

shared uint s_acc[SHARED_WORDS];

// Float sums of the current bin over the voxels of one run (at most TFM_SOLVER_RUN terms):
// entry j (lo) and j+1 (hi). Which voxels form a run is fixed by their indices, so the sums (and
// the fixed-point totals) are the same on every run; converting once per bin and run instead of
// once per term is what makes the kernel fast.
vec4 lo_sum, hi_sum;

void flush_bin(uint j) {
  FX_ADD_TF_PAIR(USE_SHARED, s_acc, accum, j, lo_sum, hi_sum)
  lo_sum = hi_sum = vec4(0.0);
}

void main() {
  const uint n = pc.opt_tf_size;
  const uint lid = gl_LocalInvocationID.x;
  if (USE_SHARED) FX_SHARED_ZERO(s_acc, TFM_TF_GRADIENT_SLOTS(n))

  uvec2 loss[4] = uvec2[4](uvec2(0u), uvec2(0u), uvec2(0u), uvec2(0u));
  lo_sum = hi_sum = vec4(0.0);
  uint cur = 0xFFFFFFFFu;
  // Each invocation walks a contiguous run (see TFM_SOLVER_RUN); runs of one workgroup are
  // adjacent, workgroups stride over blocks.
  const uint block = gl_WorkGroupSize.x * TFM_SOLVER_RUN;
  for (uint base = gl_WorkGroupID.x * block; base < pc.voxel_count; base += gl_NumWorkGroups.x * block) {
    const uint first = base + lid * TFM_SOLVER_RUN;
    const uint last = min(first + TFM_SOLVER_RUN, pc.voxel_count);
    for (uint i = first; i < last; ++i) {
      uint jr, jo;
      float wr, wo;
      if (!tf_coordinate(ref_field[i], pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr)) continue;
      if (!tf_coordinate(opt_field[i], pc.opt_lo, pc.opt_scale, n, jo, wo)) continue;
      const vec4 b = clamp((1.0 - wr) * ref_tf[jr] + wr * ref_tf[jr + 1u], 0.0, 1.0);
      const vec4 e = (1.0 - wo) * x[jo] + wo * x[jo + 1u] - b;
      const vec4 d = LOSS_L1 ? sign(e) : e;
      if (jo != cur) {
        if (cur != 0xFFFFFFFFu) flush_bin(cur);
        cur = jo;
      }
      for (uint c = 0u; c < 4u; ++c) fx_add(loss[c], fx_from_float(LOSS_L1 ? abs(e[c]) : e[c] * e[c]));
      lo_sum += (1.0 - wo) * d;
      hi_sum += wo * d;
    }
    // Sums never span runs: a run is the aligned index range [16k, 16k+16), so they do not
    // depend on the number of workgroups either.
    if (cur != 0xFFFFFFFFu) flush_bin(cur);
    cur = 0xFFFFFFFFu;
  }
  for (uint c = 0u; c < 4u; ++c) FX_ATOMIC_ADD(accum, TFM_GD_LOSS_SLOT(n) + c, loss[c]);

  if (USE_SHARED) FX_SHARED_FLUSH(s_acc, TFM_TF_GRADIENT_SLOTS(n), accum)
}
