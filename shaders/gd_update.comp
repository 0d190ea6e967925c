// One gradient-descent step on the TF (four channels, N entries) in one workgroup: decodes the
// gradient sums of gd_gradient, adds the penalty gradient, takes a Jacobi-scaled SGD step or an
// Adam step, and projects to [0,1]. No reductions: each entry is updated by one invocation.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_GD_UPDATE_PUSH
#include "solver_layout.h"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;

layout(std430, binding = TFM_GD_UPDATE_BINDING_ACCUM) readonly buffer Accum { uint accum[]; };
layout(std430, binding = TFM_GD_UPDATE_BINDING_X) buffer X { vec4 x[]; };
layout(std430, binding = TFM_GD_UPDATE_BINDING_M) buffer M { vec4 m[]; };
layout(std430, binding = TFM_GD_UPDATE_BINDING_V) buffer V { vec4 v[]; };
layout(std430, binding = TFM_GD_UPDATE_BINDING_INV_DIAG) readonly buffer InvDiag { float inv_diag[]; };
layout(std430, binding = TFM_GD_UPDATE_BINDING_GRADIENT) buffer Gradient { vec4 gradient[]; };

void main() {
  const uint n = pc.tf_size;
  const uint lid = gl_LocalInvocationID.x;
  // Pass 1: the full gradient from the old x (the smoothness term reads neighbours).
  for (uint j = lid; j < n; j += gl_WorkGroupSize.x) {
    vec4 sum;
    for (uint c = 0u; c < 4u; ++c) {
      const uint k = 4u * j + c;  // signed slot of entry j, channel c
      sum[c] = fx_signed_to_float(uvec2(accum[2u * k], accum[2u * k + 1u]));
    }
    const vec4 xj = x[j];
    vec4 d = vec4(0.0);
    if (j > 0u) d += xj - x[j - 1u];
    if (j + 1u < n) d += xj - x[j + 1u];
    gradient[j] = pc.data_scale * sum + pc.reg_scale * (pc.ridge_weight * xj + pc.smooth_weight * d);
  }
  // Every read of the old x (and write of the gradient) completes before x is overwritten.
  memoryBarrierBuffer();
  barrier();
  // Pass 2: the step, projected to [0,1].
  for (uint j = lid; j < n; j += gl_WorkGroupSize.x) {
    const vec4 g = gradient[j];
    vec4 step;
    if (pc.optimizer == TFM_GD_OPTIMIZER_ADAM) {
      const vec4 mj = pc.beta1 * m[j] + (1.0 - pc.beta1) * g;
      const vec4 vj = pc.beta2 * v[j] + (1.0 - pc.beta2) * g * g;
      m[j] = mj;
      v[j] = vj;
      step = pc.lr * (mj * pc.bias1) / (sqrt(vj * pc.bias2) + pc.epsilon);
    } else {
      step = pc.lr * g * (inv_diag[j] / pc.reg_scale);
    }
    x[j] = clamp(x[j] - step, 0.0, 1.0);
  }
}
