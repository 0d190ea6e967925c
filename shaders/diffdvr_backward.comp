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
// w times it. Empty (NaN) samples left the state unchanged and receive nothing.
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
// Gradient sums: each invocation keeps the two entries of its current TF interval in float
// registers while consecutive samples stay in it (smooth fields mostly do), converts the sums
// to signed 32.32 fixed point (fixed_point.glsl) when the interval changes, and adds them with
// integer atomics into the workgroup's shared accumulators, flushed once per workgroup into the
// global ones. Integer sums are exact, so the result does not depend on scheduling. The march
// is two nested loops, one run per outer iteration (see backpropagate_pixel).
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_RENDER_PUSH
#include "diffdvr_layout.h"
#include "fixed_point.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X, local_size_y_id = TFM_SPEC_WORKGROUP_Y) in;
layout(constant_id = TFM_DIFFDVR_SPEC_LOSS) const uint LOSS = TFM_DIFFDVR_LOSS_L2;
layout(constant_id = TFM_DIFFDVR_SPEC_SHARED_WORDS) const uint SHARED_WORDS = 2u;
layout(constant_id = TFM_DIFFDVR_SPEC_USE_SHARED) const bool USE_SHARED = true;

TFM_DECLARE_RAYMARCH_BINDINGS(TFM_DIFFDVR_BWD_BINDING_FIELD, TFM_DIFFDVR_BWD_BINDING_TF)
#include "raymarch.glsl"

layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_VIEWS) readonly buffer Views { RenderView views[]; };
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_STATE) readonly buffer State { vec4 state[]; };
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_STOP) readonly buffer Stop { uint stop_index[]; };
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_TARGET) readonly buffer Target { vec4 target[]; };
layout(std430, binding = TFM_DIFFDVR_BWD_BINDING_ACCUM) buffer Accum { uint accum[]; };

shared uint s_acc[SHARED_WORDS];

// Adds the register sums of TF entries j and j + 1 to the accumulators (run sums of one ray are
// far below fx_from_signed's 2^31).
void flush(uint j, vec4 g0, vec4 g1) { FX_ADD_TF_PAIR(USE_SHARED, s_acc, accum, j, g0, g1) }

void backpropagate_pixel(uvec2 pixel, uint view) {
  const MarchParams mp = march_params_from_push();
  const Ray ray = view_ray(views[view], pixel, mp);
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
  FX_ATOMIC_ADD_TO(USE_SHARED, s_acc, accum, 4u * mp.tf_size, fx_from_float(loss))

  const vec3 g_color = g.rgb;
  float g_trans = -g.a;  // A = 1 - T
  vec3 color = s.rgb;
  float transmittance = s.a;
  // Runs: consecutive samples in one TF interval sum their gradients in float registers (g0, g1
  // for entries cur, cur + 1); a run is flushed to the accumulators when the interval changes.
  // The inner loop marches one run and stops at the first sample of the next, whose terms start
  // the next run (n0, n1); the flush sits outside it, so it runs once per run rather than as
  // code every sample passes (CPU devices execute a branch's body whether or not a lane takes
  // it). The runs, and so the bits, are those of a flush inside the loop.
  uint k = stop_index[index];
  uint cur = 0xFFFFFFFFu;
  vec4 g0 = vec4(0.0), g1 = vec4(0.0);
  bool more = true;
  while (more) {
    uint next = 0xFFFFFFFFu;
    vec4 n0 = vec4(0.0), n1 = vec4(0.0);
    more = false;
    while (k > 0u) {
      --k;
      float value;
      if (!sample_field(sample_position(ray, k, mp.dt), mp, value)) continue;
      uint j;
      float w;
      // shade_sample() of raymarch.glsl, with the interval (j, w) and the clamp kept.
      const vec4 c = clamp(classify(value, mp, j, w), 0.0, 1.0);
      const float tau = sample_transmittance(c.a, mp);
      uncomposite(color, transmittance, c.rgb, tau);  // transmittance is now T before sample k
      const float gc_dot_c = dot(g_color, c.rgb);
      const vec3 d_rgb = g_color * (transmittance * (1.0 - tau));
      const float d_tau = transmittance * (g_trans - gc_dot_c);
      const bool clamped = c.a * mp.depth_per_alpha >= TFM_MAX_SAMPLE_OPTICAL_DEPTH;
      const float d_alpha = clamped ? 0.0 : -d_tau * mp.depth_per_alpha * tau;
      g_trans = (1.0 - tau) * gc_dot_c + tau * g_trans;
      const vec4 d = vec4(d_rgb, d_alpha);
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
  if (invocation_pixel(pixel, view)) backpropagate_pixel(pixel, view);

  if (USE_SHARED) FX_SHARED_FLUSH(s_acc, slots, accum)
}
