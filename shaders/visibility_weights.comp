// Visibility weights for weighted voxel least squares (kernels/visibility_weights.h). For voxel x
// (at its centre, index space) and a camera v:
//   T_v(x) = the transmittance of what lies in front of x seen from v's eye, under the reference
//            field and TF with the renderer's optical model (raymarch.glsl: trilinear samples, NaN
//            samples empty, the same classification and optical depth per step dt): the product
//            of tau over the samples x + k dt u, k = 1 .. K + 1, u the unit direction towards the
//            eye, s = t / dt (at most max_steps), t the distance to where the segment leaves the
//            box or reaches the eye, K = floor(s), the last sample's optical depth times s - K
//            (so the weight is continuous in t); 0 when x is outside v's view frustum. The
//            product ends (0) once it is below 2^-24, which no weight can show. No early
//            termination at the renderer's threshold: a hard cut would make the weight jump
//            where float and double round differently; 1 % of a camera is as good as unseen.
//   w(x)   = sum over the cameras of T_v(x), in camera order (so the same bits on every run).
// MODE_SUM writes w into the weight field (batches of views, or one view's rays in parts where
// they are longer, so no invocation loops longer than llvmpipe allows; later batches add to it)
// and, in the last batch, the maximum over the voxels: atomicMax of the float's bits, which order
// as the floats do for w >= 0, so it is exact and order-free. MODE_QUANTIZE replaces w by
// round(2^16 w / max) 2^-16: weights in [0, 1] that are multiples of 2^-16, exact floats the
// assembly multiplies its terms by.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "visibility_layout.h"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_VIS_SPEC_MODE) const uint MODE = TFM_VIS_MODE_SUM;

TFM_DECLARE_RAYMARCH_BINDINGS(TFM_VIS_BINDING_FIELD, TFM_VIS_BINDING_TF)
#include "raymarch.glsl"

layout(std430, binding = TFM_VIS_BINDING_VIEWS) readonly buffer Views { RenderView views[]; };
layout(std430, binding = TFM_VIS_BINDING_OUT) buffer Out { float weight[]; };
layout(std430, binding = TFM_VIS_BINDING_MAX) buffer Max { uint max_bits; };
layout(std430, binding = TFM_VIS_BINDING_PARTIAL) buffer Partial { float partial[]; };

MarchParams march_params() { return TFM_MARCH_PARAMS_OF(vp); }

// T_v(x) of the voxel at index-space point p: `transmittance` (1 for a whole ray) times the
// samples k in (k_first, k_end] of its march (k_end 0: to its end).
float transmittance_to_eye(vec3 p, RenderView v, MarchParams mp, uint k_first, uint k_end, float transmittance) {
  if (!(transmittance > 0.0)) return 0.0;
  const vec3 x = p / mp.inv_axis;  // world
  const vec3 rel = x - v.eye.xyz;  // eye -> voxel
  const float depth = dot(rel, v.forward.xyz);
  if (!(depth > 0.0)) return 0.0;
  const float tan_half_fov = v.eye.w, aspect = v.forward.w;
  if (abs(dot(rel, v.right.xyz)) > depth * tan_half_fov * aspect || abs(dot(rel, v.up.xyz)) > depth * tan_half_fov)
    return 0.0;
  const float dist = length(rel);
  const vec3 d = (-rel / dist) * mp.inv_axis;  // index-space displacement per world unit, towards the eye
  // Where the segment leaves the box [-0.5, dims - 0.5] (x is inside it), or reaches the eye.
  const vec3 box_hi = vec3(mp.dims) - 0.5;
  float t1 = dist;
  for (int a = 0; a < 3; ++a) {
    if (d[a] > 1e-30) t1 = min(t1, (box_hi[a] - p[a]) / d[a]);
    else if (d[a] < -1e-30) t1 = min(t1, (-0.5 - p[a]) / d[a]);
  }
  const float steps = min(t1 / mp.dt, float(mp.max_steps));
  const uint whole = uint(steps);
  const uint k_last = k_end == 0u ? whole + 1u : min(whole + 1u, k_end);
  for (uint k = k_first + 1u; k <= k_last; ++k) {
    // The last sample, one step past the whole ones, counts its fraction of a step: the weight
    // is continuous in the segment's length.
    const float part = k <= whole ? 1.0 : steps - float(whole);
    float value;
    if (!(part > 0.0) || !sample_field(p + (float(k) * mp.dt) * d, mp, value)) continue;
    uint j;
    float w;
    const float a = clamp(classify(value, mp, j, w), 0.0, 1.0).a;
    transmittance *= exp(-min(a * mp.depth_per_alpha, TFM_MAX_SAMPLE_OPTICAL_DEPTH) * part);
    if (transmittance < TFM_VIS_MIN_TRANSMITTANCE) return 0.0;
  }
  return transmittance;
}

void main() {
  if (gl_GlobalInvocationID.x >= vp.voxel_count) return;
  const uint i = vp.first_voxel + gl_GlobalInvocationID.x;  // voxel of the grid
  const uint o = i - vp.out_first;                          // its place in the bound weight chunk
  if (MODE == TFM_VIS_MODE_QUANTIZE) {
    const float m = uintBitsToFloat(max_bits);
    weight[o] = m > 0.0 ? min(floor(weight[o] * (65536.0 / m) + 0.5), 65536.0) * (1.0 / 65536.0) : 0.0;
    return;
  }
  const MarchParams mp = march_params();
  const uint nx = mp.dims.x, ny = mp.dims.y;
  const vec3 p = vec3(uvec3(i % nx, (i / nx) % ny, i / (nx * ny)));
  float sum = vp.view_first == 0u && vp.sample_first == 0u ? 0.0 : weight[o];
  if (vp.sample_end == 0u) {
    for (uint v = vp.view_first; v < vp.view_first + vp.view_count; ++v)
      sum += transmittance_to_eye(p, views[v], mp, 0u, 0u, 1.0);
  } else {
    // One view's rays in parts: the same samples in the same order, the float product kept
    // between the parts, so the same bits as whole rays.
    const float t = transmittance_to_eye(p, views[vp.view_first], mp, vp.sample_first, vp.sample_end,
                                         vp.sample_first == 0u ? 1.0 : partial[o]);
    if (vp.sample_end >= vp.max_steps) sum += t;
    else partial[o] = t;
  }
  weight[o] = sum;
  if (vp.finish != 0u) atomicMax(max_bits, floatBitsToUint(sum));
}
