// Loss and gradient of the voxel objective for gradient descent, over one chunk of voxels: per
// voxel e = T_o(F_o) - b (tf_residual.glsl); l2 adds e^2 to the loss and (1-w) e, w e to entries j, j+1 of the gradient
// sum; l1 adds |e| and (1-w) sign(e), w sign(e). The gradient is reduced as
// tf_pair_reduce.glsl describes, the loss per lane in registers; every term is converted to
// 32.32 fixed point on its own and summed as an integer (the same bits for every mode, atomic
// width, chunking and workgroup count). Lanes take consecutive quads of voxels in their
// subgroup's segment, read as texels, as in assemble_normal_equations.comp, which also explains
// the modes and the texel buffers (the last voxel_count % 4 voxels are read as floats;
// tf_residual_walk.glsl).
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
layout(constant_id = TFM_GD_SPEC_MODE) const uint MODE = TFM_REDUCE_RUNS_SHARED;
// Slots of the workgroup-shared gradient accumulators (1 unless MODE is RUNS_SHARED).
layout(constant_id = TFM_GD_SPEC_SHARED_SLOTS) const uint SHARED_SLOTS = 1u;
// TF entries of each lane's private histogram, and of its copy of x (0 unless MODE is PRIVATE).
layout(constant_id = TFM_GD_SPEC_PRIVATE_BINS) const uint PRIVATE_BINS = 0u;
layout(constant_id = TFM_GD_SPEC_LOSS_L1) const bool LOSS_L1 = false;
// Reference TF entries copied into private memory (0: read the buffer).
layout(constant_id = TFM_GD_SPEC_TF_CACHE) const uint TF_CACHE_ENTRIES = 0u;

layout(binding = TFM_GD_BINDING_REF_FIELD) uniform samplerBuffer ref_field;  // one voxel a texel
layout(binding = TFM_GD_BINDING_REF_QUADS) uniform samplerBuffer ref_quads;
layout(binding = TFM_GD_BINDING_OPT_FIELD) uniform samplerBuffer opt_field;
layout(binding = TFM_GD_BINDING_OPT_QUADS) uniform samplerBuffer opt_quads;
layout(std430, binding = TFM_GD_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };
layout(std430, binding = TFM_GD_BINDING_X) readonly buffer X { vec4 x[]; };
TFM_DECLARE_ACCUMULATORS(TFM_GD_BINDING_ACCUM)

#include "tf_pair_reduce.glsl"
#include "tf_residual.glsl"

Fx loss[4];

void take(float ref_value, float opt_value) {
  uint jo;
  float wo;
  vec4 b, e;
  const bool ok = voxel_residual(ref_value, opt_value, jo, wo, b, e);
  const vec4 d = LOSS_L1 ? sign(e) : e;
  for (uint c = 0u; c < 4u; ++c) fx_sum(loss[c], fx_term(LOSS_L1 ? abs(e[c]) : e[c] * e[c]));
  const float w = ok ? wo : 0.0;
  pair_add(ok, jo, (1.0 - w) * d, w * d);
}

#include "tf_residual_walk.glsl"

void main() {
  const uint n = pc.opt_tf_size;
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_ZERO(TFM_TF_GRADIENT_SLOTS(n))
  residual_begin();
  for (uint c = 0u; c < 4u; ++c) loss[c] = FX_ZERO;
  pair_begin();

  residual_walk();
  pair_end(n);
  for (uint c = 0u; c < 4u; ++c) TFM_ADD_GLOBAL(TFM_GD_LOSS_SLOT(n) + c, loss[c])

  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_FLUSH(TFM_TF_GRADIENT_SLOTS(n))
}
