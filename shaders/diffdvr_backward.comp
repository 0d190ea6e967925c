// DiffDVR backward pass with the inversion trick. Per pixel: the image loss against the target
// (l2 or l1 over RGBA, X = (C, 1 - T)), then a re-march of the ray from its final state, sample
// k_stop-1 down to 0, undoing each compositing step with uncomposite() instead of reading stored
// samples, while the adjoints flow back to the two TF entries each sample interpolates.
//
// One step (forward) is C' = C + T (1 - tau) c, T' = T tau, tau = exp(-min(a D, MAX)), with D
// the optical depth of one step at TF opacity 1. Given the adjoints gC (vec3) of C' and gT of T':
//   dL/dc   = gC T (1 - tau)
//   dL/dtau = T (gT - gC.c)
//   dL/da   = dL/dtau * (-D tau)          (0 where the clamp a D >= MAX is active)
//   gT     <- (1 - tau) gC.c + tau gT    (the adjoint of T); gC is unchanged (C' is C + ...)
// The TF lookup is (1 - w) E_j + w E_{j+1}, so E_j receives (1 - w) (dL/dc, dL/da) and E_{j+1}
// w times it. Empty samples (a corner without data: NaN, ±Inf) left the state unchanged and receive nothing.
//
// Guard near alpha = 1: the inversion T <- T / tau needs T > 0 and tau > 0 in float. The
// forward pass stops once T <= 1 - termination opacity (validate() keeps that opacity < 1),
// and the optical-depth clamp (TFM_MAX_SAMPLE_OPTICAL_DEPTH = 20) keeps every tau >= exp(-20),
// so the final T >= (1 - opacity) exp(-20) ~ 2e-11 for the default 0.99: a normal float, and
// each T recovered on the way back is larger still. The forward pass hands T over exactly
// (render_image.comp in TFM_RENDER_MODE_DIFFDVR_STATE stores T, not 1 - T). Only T enters the
// adjoint; C is inverted too (it is free: dead code the compiler drops) so the march reads as the
// forward one reversed.
//
// Gradient sums end in signed 32.32 fixed point (fixed_point.glsl): integer sums are exact, so
// the result does not depend on scheduling. How a lane gets its terms there is the build's:
//  - Default build, "runs" (GPUs): each invocation marches one pixel and keeps the two entries of
//    its current TF interval in float registers while consecutive samples stay in it (smooth
//    fields mostly do), converts the sums to fixed point when the interval changes and adds them
//    with integer atomics into the workgroup's shared accumulators (USE_SHARED), flushed once per
//    workgroup into the global ones, or straight into the global ones. The march is two nested
//    loops, one run per outer iteration, or on devices with a loop limit one flat loop with the
//    same bits (see backpropagate_runs).
//  - TFM_DIFFDVR_PRIVATE build (CPU devices such as lavapipe): each invocation marches
//    PIXELS_PER_LANE pixels (rows 16 apart, so a workgroup steps through 16x16 tiles), each ray in
//    one flat loop, and adds every sample to its own float histogram of the TF entries (a vec4 per entry),
//    without atomics or branches. At the end the lanes of a subgroup sum their histograms
//    exactly (each entry converted to fixed point, then subgroupAdd on 16-bit pieces, which
//    cannot overflow) and one lane adds the sum to the global accumulators. On lavapipe, lanes
//    are the SIMD lanes of one CPU thread: every atomic is a loop over the lanes and a loop that
//    one lane leaves keeps the others waiting, so the runs build spent most of its time in the
//    run loop and the flushes (measured, 8 views of 512^2 of a 128^3 field, 64 entries: backward
//    pass 7.1-7.7 s with runs, 3.2-4.3 s with private histograms of 4 pixels per lane).
// Both builds are deterministic (a lane's float sums follow its samples in order); they sum the
// same terms in different float groupings, so their bits differ slightly from each other. The
// private build's grouping also depends on which rows a dispatch covers: row bands that cut a
// lane's 4 rows give other (equally close) bits than one dispatch over the image.
#version 450
#extension GL_GOOGLE_include_directive : require
#ifdef TFM_DIFFDVR_PRIVATE
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#endif
#define TFM_WANT_RENDER_PUSH
#include "diffdvr_layout.h"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X, local_size_y_id = TFM_SPEC_WORKGROUP_Y) in;
layout(constant_id = TFM_DIFFDVR_SPEC_LOSS) const uint LOSS = TFM_DIFFDVR_LOSS_L2;
layout(constant_id = TFM_DIFFDVR_SPEC_SHARED_WORDS) const uint SHARED_WORDS = 2u;
layout(constant_id = TFM_DIFFDVR_SPEC_USE_SHARED) const bool USE_SHARED = true;
// TFM_DIFFDVR_PRIVATE: the entries of a lane's histogram (the TF size) and its pixels.
layout(constant_id = TFM_DIFFDVR_SPEC_PRIVATE_BINS) const uint PRIVATE_BINS = 2u;
layout(constant_id = TFM_DIFFDVR_SPEC_PIXELS_PER_LANE) const uint PIXELS_PER_LANE = 1u;
// Default build: march a ray's runs in one loop (see backpropagate_runs).
layout(constant_id = TFM_DIFFDVR_SPEC_FLAT_RUNS) const bool FLAT_RUNS = false;

TFM_DECLARE_RAYMARCH_BINDINGS(TFM_DIFFDVR_BWD_BINDING_FIELD, TFM_DIFFDVR_BWD_BINDING_TF)
#include "raymarch.glsl"

layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_VIEWS) readonly buffer Views { RenderView views[]; };
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_STATE) readonly buffer State { vec4 state[]; };
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_STOP) readonly buffer Stop { uint stop_index[]; };
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_TARGET) readonly buffer Target { vec4 target[]; };
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_ACCUM) buffer Accum { uint accum[]; };

shared uint s_acc[SHARED_WORDS];

// The state of one re-marched ray: its camera ray, the state (C, T) before the next sample to
// undo, the adjoints of C and T, and that sample's index plus one.
struct Adjoint {
  Ray ray;
  vec3 color;
  float transmittance;
  vec3 g_color;
  float g_trans;
  uint k;
};

// The pixel's loss against its target, and its ray at the final state with the loss's adjoints.
float begin_pixel(uvec2 pixel, uint view, MarchParams mp, out Adjoint a) {
  const uint index = pixel_index(pixel, view);
  const vec4 s = state[index];
  const vec4 t = target[index];
  // Images as the renderer writes them: (C, opacity = 1 - T).
  const vec4 diff = vec4(s.rgb, 1.0 - s.a) - vec4(t.rgb, 1.0 - t.a);
  vec4 g;  // dLoss / d(C, A); sign(0) = 0 where the images agree exactly (missed rays)
  float loss;
  if (LOSS == TFM_DIFFDVR_LOSS_L1) {
    g = sign(diff);
    loss = abs(diff.r) + abs(diff.g) + abs(diff.b) + abs(diff.a);
  } else {
    g = 2.0 * diff;
    loss = dot(diff, diff);
  }
  a.ray = view_ray(views[view], pixel, mp);
  a.color = s.rgb;
  a.transmittance = s.a;
  a.g_color = g.rgb;
  a.g_trans = -g.a;  // A = 1 - T
  a.k = stop_index[index];
  return loss;
}

// Undoes sample a.k - 1 (a.k > 0) and moves on to the one before. False for an empty sample;
// else its TF interval (j, w) and d = dLoss/d(rgb, a) of the sample's classified colour.
bool step_back(MarchParams mp, inout Adjoint a, out uint j, out float w, out vec4 d) {
  --a.k;
  float value;
  j = 0u;
  w = 0.0;
  d = vec4(0.0);
  if (!sample_field(sample_position(a.ray, a.k, mp.dt), mp, value)) return false;
  // shade_sample() of raymarch.glsl, with the interval (j, w) and the clamp kept.
  const vec4 c = clamp(classify(value, mp, j, w), 0.0, 1.0);
  const float tau = sample_transmittance(c.a, a.ray);
  uncomposite(a.color, a.transmittance, c.rgb, tau);  // transmittance is now T before sample k
  const float gc_dot_c = dot(a.g_color, c.rgb);
  const vec3 d_rgb = a.g_color * (a.transmittance * (1.0 - tau));
  const float d_tau = a.transmittance * (a.g_trans - gc_dot_c);
  const bool clamped = c.a * a.ray.depth_per_alpha >= TFM_MAX_SAMPLE_OPTICAL_DEPTH;
  const float d_alpha = clamped ? 0.0 : -d_tau * a.ray.depth_per_alpha * tau;
  a.g_trans = (1.0 - tau) * gc_dot_c + tau * a.g_trans;
  d = vec4(d_rgb, d_alpha);
  return true;
}

#ifndef TFM_DIFFDVR_PRIVATE

// Rays marched back in parts (rp.sample_end != 0, devices that limit an invocation's loops): each
// part marches samples [rp.first_sample, rp.sample_end) and leaves the state and its adjoints here
// for the part before them, which the next dispatch marches.
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_RESUME) buffer Resume { vec4 resume[]; };

// The ray of `pixel` where the part after this one left it.
void resume_pixel(uvec2 pixel, uint view, MarchParams mp, out Adjoint a) {
  const uint index = pixel_index(pixel, view);
  const vec4 s = resume[2u * index], g = resume[2u * index + 1u];
  a.ray = view_ray(views[view], pixel, mp);
  a.color = s.rgb;
  a.transmittance = s.a;
  a.g_color = g.rgb;
  a.g_trans = g.a;
  a.k = stop_index[index];
}

// Adds the register sums of TF entries j and j + 1 to the accumulators (run sums of one ray are
// far below fx_from_signed's 2^31).
void flush(uint j, vec4 g0, vec4 g1) { FX_ADD_TF_PAIR(USE_SHARED, s_acc, accum, j, g0, g1) }

void backpropagate_runs(uvec2 pixel, uint view) {
  const MarchParams mp = march_params_from_push();
  Adjoint a;
  // Whole rays (sample_end 0), or the part of a ray that ends at its last sample, begin it: the
  // loss and its adjoints. Samples below `lo` are another part's.
  const uint lo = rp.first_sample;
  if (rp.sample_end == 0u || rp.sample_end >= rp.max_steps) {
    const float loss = begin_pixel(pixel, view, mp, a);
    FX_ATOMIC_ADD_TO(USE_SHARED, s_acc, accum, 4u * mp.tf_size, fx_from_float(loss))
  } else {
    resume_pixel(pixel, view, mp, a);
  }
  if (rp.sample_end != 0u) a.k = min(a.k, rp.sample_end);
  // Runs: consecutive samples in one TF interval sum their gradients in float registers (g0, g1
  // for entries cur, cur + 1); a run is flushed to the accumulators when the interval changes.
  uint cur = 0xFFFFFFFFu;
  vec4 g0 = vec4(0.0), g1 = vec4(0.0);
  if (FLAT_RUNS) {
    // One loop iteration a sample, the flush inside it: devices with a loop limit (llvmpipe),
    // where the two loops below could cost up to ten iterations a sample (a SIMD vector's lanes
    // end their runs at different samples). Same runs and sums, so the same bits (0 + x = x).
    // Rays in parts flush their last run at each part's edge and store their state.
    while (a.k > lo) {
      uint j;
      float w;
      vec4 d;
      if (!step_back(mp, a, j, w, d)) continue;
      if (cur != 0xFFFFFFFFu && j != cur) {
        flush(cur, g0, g1);
        g0 = g1 = vec4(0.0);
      }
      cur = j;
      g0 += (1.0 - w) * d;
      g1 += w * d;
    }
    if (cur != 0xFFFFFFFFu) flush(cur, g0, g1);
    if (lo > 0u) {
      const uint index = pixel_index(pixel, view);
      resume[2u * index] = vec4(a.color, a.transmittance);
      resume[2u * index + 1u] = vec4(a.g_color, a.g_trans);
    }
    return;
  }
  // The inner loop marches one run and stops at the first sample of the next, whose terms start
  // the next run (n0, n1); the flush sits outside it, so it runs once per run rather than as
  // code every sample passes. The runs, and so the bits, are those of a flush inside the loop.
  bool more = true;
  while (more) {
    uint next = 0xFFFFFFFFu;
    vec4 n0 = vec4(0.0), n1 = vec4(0.0);
    more = false;
    while (a.k > lo) {
      uint j;
      float w;
      vec4 d;
      if (!step_back(mp, a, j, w, d)) continue;
      if (cur != 0xFFFFFFFFu && j != cur) {
        next = j;
        n0 = (1.0 - w) * d;
        n1 = w * d;
        more = true;
        break;
      }
      cur = j;
      g0 += (1.0 - w) * d;
      g1 += w * d;
    }
    if (cur != 0xFFFFFFFFu) flush(cur, g0, g1);
    cur = next;
    g0 = n0;
    g1 = n1;
  }
}

void main() {
  const uint slots = TFM_DIFFDVR_SLOTS(rp.tf_size);
  if (USE_SHARED) FX_SHARED_ZERO(s_acc, slots)

  // No early return: every invocation must reach the flush's barrier.
  uvec2 pixel;
  uint view;
  if (invocation_pixel(pixel, view)) backpropagate_runs(pixel, view);

  if (USE_SHARED) FX_SHARED_FLUSH(s_acc, slots, accum)
}

#else  // TFM_DIFFDVR_PRIVATE

// The lane's gradient sums per TF entry, one array per channel (lavapipe compiles four arrays of
// N floats faster than one of N vec4s: assemble_normal_equations.comp).
float hist_r[PRIVATE_BINS], hist_g[PRIVATE_BINS], hist_b[PRIVATE_BINS], hist_a[PRIVATE_BINS];
void hist_add(uint j, vec4 v) { hist_r[j] += v.r, hist_g[j] += v.g, hist_b[j] += v.b, hist_a[j] += v.a; }
uvec2 lane_loss;          // the lane's loss, fixed point
uint hist_lo, hist_hi;    // the entries the lane touched: [hist_lo, hist_hi]

void backpropagate_private(uvec2 pixel, uint view) {
  const MarchParams mp = march_params_from_push();
  Adjoint a;
  fx_add(lane_loss, fx_from_float(begin_pixel(pixel, view, mp, a)));
  while (a.k > 0u) {
    uint j;
    float w;
    vec4 d;
    // An empty sample gives d = 0 at entry 0: adding it changes nothing and needs no branch.
    const bool ok = step_back(mp, a, j, w, d);
    hist_add(j, (1.0 - w) * d);
    hist_add(j + 1u, w * d);
    hist_lo = ok ? min(hist_lo, j) : hist_lo;
    hist_hi = ok ? max(hist_hi, j + 1u) : hist_hi;
  }
}

// Adds slot k of every lane of the subgroup to the global accumulators: one lane adds the exact
// 64-bit sum, formed from subgroup sums of the low word's 16-bit halves (each below 2^32 for any
// subgroup size up to 2^16) and of the high word (modulo 2^32, the sum's own wrap-around).
void subgroup_add(uint k, uvec2 v) {
  if (!subgroupAny((v.x | v.y) != 0u)) return;
  const uint lo = subgroupAdd(v.x & 0xFFFFu), mid = subgroupAdd(v.x >> 16u), hi = subgroupAdd(v.y);
  if (subgroupElect()) {
    uvec2 total = uvec2(lo, hi);
    fx_add(total, uvec2(mid << 16u, mid >> 16u));
    FX_ATOMIC_ADD(accum, k, total)
  }
}

void main() {
  const uint n = rp.tf_size;
  for (uint e = 0u; e < n; ++e) hist_r[e] = hist_g[e] = hist_b[e] = hist_a[e] = 0.0;
  lane_loss = uvec2(0u);
  hist_lo = n;
  hist_hi = 0u;
  // Pixel p of the lane is in the p-th 16x16 tile of its workgroup's column of tiles.
  const uint first_row = rp.row_offset + gl_WorkGroupID.y * PIXELS_PER_LANE * gl_WorkGroupSize.y;
  for (uint p = 0u; p < PIXELS_PER_LANE; ++p) {
    const uvec2 pixel = uvec2(gl_GlobalInvocationID.x, first_row + p * gl_WorkGroupSize.y + gl_LocalInvocationID.y);
    if (pixel_in_dispatch(pixel, gl_GlobalInvocationID.z)) backpropagate_private(pixel, gl_GlobalInvocationID.z);
  }
  // Every lane of the subgroup is here (no early return), as the subgroup operations require.
  // Lane sums of the histogram are far below fx_from_signed's 2^31 (DiffDvrGradient bounds a
  // whole band's sums by that).
  const uint lo = subgroupMin(hist_lo), hi = subgroupMax(hist_hi);
  for (uint e = lo; e <= hi && lo < n; ++e) {
    const vec4 g = vec4(hist_r[e], hist_g[e], hist_b[e], hist_a[e]);
    for (uint c = 0u; c < 4u; ++c) subgroup_add(4u * e + c, fx_from_signed(g[c]));
  }
  subgroup_add(4u * n, lane_loss);
}

#endif
