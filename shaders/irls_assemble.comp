// One pass of iteratively reweighted least squares for the l1 voxel loss (solver `irls`), over
// one chunk of voxels: at the current TF x, per voxel and channel, e = T_o(F_o) - b as in
// gd_gradient.comp (T_o = x, b = T_r(F_r) clamped to [0,1]) and the weight
//   w_c = delta_c / max(|e_c|, delta_c)   in (0, 1],
// the majorizer of the Huber loss with threshold delta_c at x, scaled so that every term below
// is a float in [0, 1]. The pass sums the weighted tridiagonal normal equations of each channel
// (w (1-t)^2, w t^2, w (1-t) t, w (1-t) b, w t b: solver_layout.h lists the slots) and the l1
// loss sum |e_c| at x; the host solves the four small systems and starts the next pass. Voxels
// without data in both fields add nothing. Terms are converted to 32.32 fixed point one by one
// and summed as integers (tf_pair_reduce.glsl with three sets): the same bits for every mode,
// atomic width, chunking and workgroup count. Lanes walk quads of voxels as in gd_gradient.comp.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#ifdef TFM_INT64
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#endif
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "solver_layout.h"
#include "tf_common.glsl"
#include "fixed_point_accumulators.glsl"
#include "quad_segments.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_IRLS_SPEC_MODE) const uint MODE = TFM_REDUCE_RUNS_SHARED;
// Slots of the workgroup-shared accumulators (1 unless MODE is RUNS_SHARED).
layout(constant_id = TFM_IRLS_SPEC_SHARED_SLOTS) const uint SHARED_SLOTS = 1u;
// TF entries of each lane's private histograms and of its copy of x (0 unless MODE is PRIVATE).
layout(constant_id = TFM_IRLS_SPEC_PRIVATE_BINS) const uint PRIVATE_BINS = 0u;
// Reference TF entries copied into private memory (0: read the buffer).
layout(constant_id = TFM_IRLS_SPEC_TF_CACHE) const uint TF_CACHE_ENTRIES = 0u;

layout(binding = TFM_IRLS_BINDING_REF_FIELD) uniform samplerBuffer ref_field;  // one voxel a texel
layout(binding = TFM_IRLS_BINDING_REF_QUADS) uniform samplerBuffer ref_quads;
layout(binding = TFM_IRLS_BINDING_OPT_FIELD) uniform samplerBuffer opt_field;
layout(binding = TFM_IRLS_BINDING_OPT_QUADS) uniform samplerBuffer opt_quads;
layout(std430, binding = TFM_IRLS_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };
layout(std430, binding = TFM_IRLS_BINDING_STATE) readonly buffer State { vec4 x[]; };  // x, then delta
TFM_DECLARE_ACCUMULATORS(TFM_IRLS_BINDING_ACCUM)

#define TFM_PAIR_SETS TFM_IRLS_SETS
#define TFM_PAIR_SET_STRIDE TFM_TF_GRADIENT_SLOTS(pc.opt_tf_size)
#include "tf_pair_reduce.glsl"
#include "tf_residual.glsl"

Fx loss[4];
vec4 delta;

void take(float ref_value, float opt_value) {
  uint jo;
  float wo;
  vec4 b, e;
  const bool ok = voxel_residual(ref_value, opt_value, jo, wo, b, e);
  for (uint c = 0u; c < 4u; ++c) fx_sum(loss[c], fx_term(abs(e[c])));
  const vec4 w = ok ? delta / max(abs(e), delta) : vec4(0.0);
  const float t = ok ? wo : 0.0;
  // Each product rounded once to a float in [0, 1].
  precise const vec4 lo_w = (1.0 - t) * w, hi_w = t * w;
  precise const vec4 diag_lo = (1.0 - t) * lo_w, diag_hi = t * hi_w, off = t * lo_w;
  precise const vec4 rhs_lo = lo_w * b, rhs_hi = hi_w * b;
  pair_add_set(TFM_IRLS_SET_DIAG, ok, jo, diag_lo, diag_hi);
  pair_add_set(TFM_IRLS_SET_OFF, ok, jo, off, vec4(0.0));
  pair_add_set(TFM_IRLS_SET_RHS, ok, jo, rhs_lo, rhs_hi);
}

#include "tf_residual_walk.glsl"

void main() {
  const uint n = pc.opt_tf_size;
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_ZERO(TFM_IRLS_LOSS_SLOT(n))
  residual_begin();
  delta = x[n];
  for (uint c = 0u; c < 4u; ++c) loss[c] = FX_ZERO;
  pair_begin();

  residual_walk();
  pair_end(n);
  for (uint c = 0u; c < 4u; ++c) TFM_ADD_GLOBAL(TFM_IRLS_LOSS_SLOT(n) + c, loss[c])

  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_FLUSH(TFM_IRLS_LOSS_SLOT(n))
}
