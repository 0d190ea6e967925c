// The TF-sized steps of preconditioned CGLS (Bjorck's PCGLS), four independent channels at once,
// in one workgroup: loops over the N entries and reduces dot products in shared memory in a fixed
// order, so every run gives the same bits. Stages (push constant): INIT, STEP, DIRECTION; see
// solver_layout.h. The voxel-sized products S p and S^T r come from sparse_gather/scatter. The
// preconditioner P = L D L^T is applied entry by entry when L = I (Jacobi) and otherwise by forward
// and backward substitution, each a first-order linear recurrence solved as a scan: every invocation
// runs over its own segment of ceil(N / W) entries twice, and the segments' maps are composed in
// log2 W steps. (One invocation's sweep over all N entries is 2N dependent steps, slow on a GPU,
// and wrong on lavapipe beyond N ~ 32 000: llvmpipe silently ends an invocation's loops once they
// have run 65535 iterations in all.)
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

shared float scan_a[gl_WorkGroupSize.x];
shared vec4 scan_b[gl_WorkGroupSize.x];

// The entries [first, end) of this invocation's segment of the substitution (ceil(N / W) each; the
// last ones may be empty).
uvec2 segment(uint n) {
  const uint length = (n + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
  const uint first = min(gl_LocalInvocationID.x * length, n);
  return uvec2(first, min(first + length, n));
}

// The step of a substitution at entry j: u_j = a u_prev + b, from z_store[j]. Forward (L y = s):
// y_j = s_j - L_{j,j-1} y_{j-1}. Backward (D L^T z = y): z_j = y_j / D_j - L_{j+1,j} z_{j+1}. The
// multipliers are at most 1 in magnitude (P is diagonally dominant: every pivot is >= smooth), so
// the products the scan forms stay bounded.
float step_a(uint j, uint n, bool backward) {
  if (backward) return j + 1u < n ? -lower[j] : 0.0;
  return j > 0u ? -lower[j - 1u] : 0.0;
}
vec4 step_b(uint j, bool backward) { return backward ? inv_pivot[j] * z_store[j] : z_store[j]; }

// The value entering this invocation's segment: the segments before it (after it, backward)
// composed by an inclusive scan of the maps u_out = a u_in + b, in a fixed order.
vec4 segment_input(float a, vec4 b, bool backward) {
  const uint w = gl_WorkGroupSize.x;
  const uint pos = backward ? w - 1u - gl_LocalInvocationID.x : gl_LocalInvocationID.x;
  // Every invocation has read the previous substitution's scan before it is overwritten.
  barrier();
  scan_a[pos] = a;
  scan_b[pos] = b;
  // Every segment's map is visible before the first level composes them.
  memoryBarrierShared();
  barrier();
  for (uint offset = 1u; offset < w; offset *= 2u) {
    float before_a = 1.0;
    vec4 before_b = vec4(0.0);
    if (pos >= offset) {
      before_a = scan_a[pos - offset];
      before_b = scan_b[pos - offset];
    }
    // Every invocation has read this level's inputs before any is overwritten.
    barrier();
    scan_b[pos] = a * before_b + b;
    scan_a[pos] = a * before_a;
    a = scan_a[pos];
    b = scan_b[pos];
    // This level's maps are visible before the next level reads them.
    memoryBarrierShared();
    barrier();
  }
  return pos > 0u ? scan_b[pos - 1u] : vec4(0.0);
}

// One substitution over z_store in place: each invocation composes its segment's map, the scan
// gives each segment its input, and each invocation runs its segment again from that input.
void substitute_pass(uint n, bool backward) {
  const uvec2 seg = segment(n);
  float a = 1.0;
  vec4 b = vec4(0.0);
  for (uint i = seg.x; i < seg.y; ++i) {
    const uint j = backward ? seg.y - 1u - (i - seg.x) : i;
    const float aj = step_a(j, n, backward);
    a *= aj;
    b = aj * b + step_b(j, backward);
  }
  vec4 u = segment_input(a, b, backward);
  for (uint i = seg.x; i < seg.y; ++i) {
    const uint j = backward ? seg.y - 1u - (i - seg.x) : i;
    u = step_a(j, n, backward) * u + step_b(j, backward);
    z_store[j] = u;
  }
}

// z = P^-1 s in place in z_store, which holds s on entry (every invocation's entries). With L = I
// the caller scales entry by entry instead (z = inv_pivot * s) and never calls this.
void substitute(uint n) {
  // Every invocation's s_j is in z_store before the segments read it.
  memoryBarrierBuffer();
  barrier();
  substitute_pass(n, false);
  // A segment's y is read backward by the invocation that wrote it: no barrier needed between.
  substitute_pass(n, true);
  // Every segment's z is visible to every invocation before any reads it.
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
      // The float32 floor: x holds each entry to half an ulp, e_j <= u |x_j| / 2 (u = 2^-24),
      // which moves s by R e, a residual no iteration removes. It is measured in P^-1's norm,
      // gz = s^T P^-1 s: P >= R / 2 (diag(M) + R, or Jacobi's diagonal, which bounds R / 2), so
      // the rounding's share is at most 2 e^T R e <= (ridge + 4 smooth) u^2 ||x||^2 / 2, and a
      // channel whose gz is down to it stops. In the plain norm the same rounding is as large as
      // a smooth error that P^-1 weighs far more, so a floor there stopped heavy smoothing at large
      // N while x was still 0.04 from the fit. 0 without R.
      const vec4 floor_gz = exp2(-48.0) * (pc.ridge_weight + 4.0 * pc.smooth_weight) * xx;
      const bvec4 converged = lessThanEqual(ss, pc.tolerance2 * s0);
      const bvec4 at_floor = lessThanEqual(gz, floor_gz);
      for (uint c = 0u; c < 4u; ++c) {
        if (converged[c] || at_floor[c] || !(gz[c] > 0.0)) state.running[c] = 0u;
      }
    }
  }
}
