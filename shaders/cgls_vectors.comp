// The TF-sized steps of preconditioned CGLS (Bjorck's PCGLS), four independent channels at once,
// in one workgroup: loops over the N entries and reduces dot products in shared memory in a fixed
// order, so every run gives the same bits. Stages (push constant): INIT, STEP, DIRECTION; see
// solver_layout.h. The voxel-sized products S p and S^T r come from sparse_gather/scatter. The
// preconditioner P = L D L^T is applied entry by entry when L = I (Jacobi) and by one invocation's
// forward and backward substitution otherwise: 2N dependent steps, small beside the voxel passes.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_CGLS_PUSH
#include "solver_layout.h"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;  // a power of two (the reduction halves it)

layout(std430, binding = TFM_CGLS_BINDING_S_ACCUM) readonly buffer SAccum { uint s_accum[]; };
layout(std430, binding = TFM_CGLS_BINDING_DELTA_ACCUM) readonly buffer DeltaAccum { uint delta_accum[]; };
layout(std430, binding = TFM_CGLS_BINDING_INV_PIVOT) readonly buffer InvPivot { float inv_pivot[]; };
layout(std430, binding = TFM_CGLS_BINDING_LOWER) readonly buffer Lower { float lower[]; };
// Written by one invocation and read by all: coherent, so the barrier makes the writes visible.
layout(std430, binding = TFM_CGLS_BINDING_Z) coherent buffer Z { vec4 z_store[]; };
layout(std430, binding = TFM_CGLS_BINDING_X) buffer X { vec4 x[]; };
layout(std430, binding = TFM_CGLS_BINDING_P) buffer P { vec4 p[]; };
layout(std430, binding = TFM_CGLS_BINDING_STATE) buffer State { CglsState state; };

shared vec4 red_a[gl_WorkGroupSize.x];
shared vec4 red_b[gl_WorkGroupSize.x];

// Sums a and b over the workgroup (same tree every run); every invocation gets the totals.
void reduce2(inout vec4 a, inout vec4 b) {
  const uint lid = gl_LocalInvocationID.x;
  // Every invocation has read the previous call's totals before they are overwritten.
  barrier();
  red_a[lid] = a;
  red_b[lid] = b;
  // Every invocation's terms are visible before the first level adds them.
  memoryBarrierShared();
  barrier();
  for (uint half_size = gl_WorkGroupSize.x / 2u; half_size > 0u; half_size /= 2u) {
    if (lid < half_size) {
      red_a[lid] += red_a[lid + half_size];
      red_b[lid] += red_b[lid + half_size];
    }
    // This level's sums are visible before the next level reads them.
    memoryBarrierShared();
    barrier();
  }
  a = red_a[0];
  b = red_b[0];
}

shared vec4 red_max[gl_WorkGroupSize.x];

// Largest |p_j| over the workgroup's entries, as the power of two p_scale >= it (1 when 0).
vec4 p_scale_of(vec4 local_max) {
  const uint lid = gl_LocalInvocationID.x;
  red_max[lid] = local_max;
  // Every invocation's maximum is visible before the first level compares them.
  memoryBarrierShared();
  barrier();
  for (uint half_size = gl_WorkGroupSize.x / 2u; half_size > 0u; half_size /= 2u) {
    if (lid < half_size) red_max[lid] = max(red_max[lid], red_max[lid + half_size]);
    // This level's maxima are visible before the next level reads them.
    memoryBarrierShared();
    barrier();
  }
  const vec4 m = red_max[0];
  vec4 scale;
  for (uint c = 0u; c < 4u; ++c) {
    int e;
    frexp(m[c], e);  // m = f 2^e, f in [0.5, 1): 2^e > m, exactly a power of two
    scale[c] = m[c] > 0.0 ? ldexp(1.0, e) : 1.0;
  }
  return scale;
}

// S^T r of entry j (4 channels) from the signed accumulators.
vec4 s_entry(uint j) {
  vec4 s;
  for (uint c = 0u; c < 4u; ++c) {
    const uint k = 4u * j + c;  // signed slot of entry j, channel c
    s[c] = fx_signed_to_float(uvec2(s_accum[2u * k], s_accum[2u * k + 1u]));
  }
  return s;
}

// (R v)_j for R = ridge I + smooth D^T D (first differences), on the x and p vectors.
vec4 r_times_x(uint j, uint n) {
  vec4 d = vec4(0.0);
  if (j > 0u) d += x[j] - x[j - 1u];
  if (j + 1u < n) d += x[j] - x[j + 1u];
  return pc.ridge_weight * x[j] + pc.smooth_weight * d;
}
vec4 r_times_p(uint j, uint n) {
  vec4 d = vec4(0.0);
  if (j > 0u) d += p[j] - p[j - 1u];
  if (j + 1u < n) d += p[j] - p[j + 1u];
  return pc.ridge_weight * p[j] + pc.smooth_weight * d;
}

// z = P^-1 s in place in z_store, which holds s on entry (every invocation's entries). With L = I
// the caller scales entry by entry instead (z = inv_pivot * s) and never calls this.
void substitute(uint n) {
  // Every invocation's s_j is in z_store before the sweep reads it.
  memoryBarrierBuffer();
  barrier();
  if (gl_LocalInvocationID.x == 0u) {
    vec4 y = z_store[0];
    for (uint j = 1u; j < n; ++j) {  // L y = s
      y = z_store[j] - lower[j - 1u] * y;
      z_store[j] = y;
    }
    vec4 w = inv_pivot[n - 1u] * y;  // D L^T z = y
    z_store[n - 1u] = w;
    for (uint j = n - 1u; j > 0u; --j) {
      w = inv_pivot[j - 1u] * z_store[j - 1u] - lower[j - 1u] * w;
      z_store[j - 1u] = w;
    }
  }
  // The sweep's z is visible to every invocation before any reads it.
  memoryBarrierBuffer();
  barrier();
}

// z = P^-1 s of entry j after substitute() (or directly with L = I).
vec4 z_entry(uint j, vec4 s) { return pc.bidiagonal != 0u ? z_store[j] : inv_pivot[j] * s; }

void main() {
  const uint n = pc.tf_size;
  const uint lid = gl_LocalInvocationID.x;
  const uvec4 running = state.running;
  const bvec4 on = notEqual(running, uvec4(0u));
  const vec4 gamma = state.gamma;

  if (pc.stage == TFM_CGLS_STAGE_INIT) {
    vec4 gz = vec4(0.0), ss = vec4(0.0), pmax = vec4(0.0);
    if (pc.bidiagonal != 0u) {
      for (uint j = lid; j < n; j += gl_WorkGroupSize.x) z_store[j] = s_entry(j);
      substitute(n);
    }
    for (uint j = lid; j < n; j += gl_WorkGroupSize.x) {
      const vec4 s = s_entry(j);  // x = 0: s = S^T b
      const vec4 z = z_entry(j, s);
      x[j] = vec4(0.0);
      p[j] = z;
      gz += s * z;
      ss += s * s;
      pmax = max(pmax, abs(z));
    }
    reduce2(gz, ss);
    const vec4 scale = p_scale_of(pmax);
    if (lid == 0u) {
      state.p_scale = scale;
      state.gamma = gz;
      state.alpha = vec4(0.0);
      state.s_norm2 = ss;
      state.s0_norm2 = ss;
      state.iterations = uvec4(0u);
      // A channel with S^T b = 0 is solved by x = 0.
      state.running = uvec4(greaterThan(ss, vec4(0.0))) * uvec4(greaterThan(gz, vec4(0.0)));
    }
  } else if (pc.stage == TFM_CGLS_STAGE_STEP) {
    vec4 prp = vec4(0.0), unused = vec4(0.0);
    for (uint j = lid; j < n; j += gl_WorkGroupSize.x) prp += p[j] * r_times_p(j, n);
    reduce2(prp, unused);
    vec4 delta;
    for (uint c = 0u; c < 4u; ++c) delta[c] = fx_to_float(uvec2(delta_accum[2u * c], delta_accum[2u * c + 1u]));
    const vec4 scale = state.p_scale;
    delta = delta * scale * scale + prp;
    // delta = ||A p||^2 > 0 unless p lies in the null space (breakdown): stop that channel.
    const bvec4 ok = greaterThan(delta, vec4(0.0));
    vec4 alpha = vec4(0.0);
    for (uint c = 0u; c < 4u; ++c) alpha[c] = (on[c] && ok[c]) ? gamma[c] / delta[c] : 0.0;
    for (uint j = lid; j < n; j += gl_WorkGroupSize.x) x[j] += alpha * p[j];
    if (lid == 0u) {
      state.alpha = alpha;
      state.running = running * uvec4(ok);
    }
  } else {  // TFM_CGLS_STAGE_DIRECTION
    vec4 gz = vec4(0.0), ss = vec4(0.0);
    if (pc.bidiagonal != 0u) {
      for (uint j = lid; j < n; j += gl_WorkGroupSize.x) z_store[j] = s_entry(j) - r_times_x(j, n);
      substitute(n);
    }
    vec4 xx = vec4(0.0), unused = vec4(0.0);
    for (uint j = lid; j < n; j += gl_WorkGroupSize.x) {
      const vec4 s = s_entry(j) - r_times_x(j, n);
      gz += s * z_entry(j, s);
      ss += s * s;
      xx += x[j] * x[j];
    }
    reduce2(gz, ss);
    reduce2(xx, unused);
    vec4 beta = vec4(0.0);
    for (uint c = 0u; c < 4u; ++c) beta[c] = on[c] ? gz[c] / gamma[c] : 0.0;
    vec4 pmax = vec4(0.0);
    for (uint j = lid; j < n; j += gl_WorkGroupSize.x) {
      const vec4 z = z_entry(j, s_entry(j) - r_times_x(j, n));
      const vec4 pj = mix(p[j], z + beta * p[j], on);
      p[j] = pj;
      pmax = max(pmax, abs(pj));
    }
    const vec4 scale = p_scale_of(pmax);
    if (lid == 0u) {
      state.p_scale = scale;
      const vec4 s0 = state.s0_norm2;
      state.gamma = mix(gamma, gz, on);
      state.s_norm2 = mix(state.s_norm2, ss, on);
      state.iterations += running;
      // The float32 floor: x holds each entry to half an ulp, u |x_j| (u = 2^-24), and R turns
      // that into an error of s up to ||R|| u ||x|| (||R|| <= ridge + 4 smooth) that no iteration
      // removes; a channel whose residual is down to it stops. 0 without R.
      const float amp = exp2(-24.0) * (pc.ridge_weight + 4.0 * pc.smooth_weight);
      const bvec4 done = lessThanEqual(ss, max(pc.tolerance2 * s0, amp * amp * xx));
      for (uint c = 0u; c < 4u; ++c) {
        if (done[c] || !(gz[c] > 0.0)) state.running[c] = 0u;
      }
    }
  }
}
