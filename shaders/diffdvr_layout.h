// Interface of the DiffDVR kernels (diffdvr_forward.comp, diffdvr_backward.comp), shared by GLSL
// and C++: bindings, tiles, specialization-constant ids and the gradient accumulator layout. Both
// kernels take the renderer's push block (RenderPush of render_layout.h, filled by
// make_render_push) and camera records, so they march exactly the renderer's rays and samples.
#ifndef TFMATCH_DIFFDVR_LAYOUT_H
#define TFMATCH_DIFFDVR_LAYOUT_H

#include "render_layout.h"

// ---- diffdvr_forward.comp -------------------------------------------------------------------
// render_image.comp's forward march, but the state written per pixel is (C, T): premultiplied
// colour and the transmittance itself. The backward pass divides T by each sample's tau, so it
// needs T exactly; 1 - (1 - T) in float loses it (to 0 when T < 6e-8).
// Specialization constants: workgroup x, y (TFM_SPEC_WORKGROUP_X/Y, both TFM_RENDER_TILE), field
// chunks (TFM_RENDER_SPEC_CHUNKS).
#define TFM_DIFFDVR_FORWARD_TILE TFM_RENDER_TILE
#define TFM_DIFFDVR_FWD_BINDING_FIELD 0  // float chunks [TFM_RENDER_MAX_CHUNKS]
#define TFM_DIFFDVR_FWD_BINDING_TF 1     // vec4 TF entries
#define TFM_DIFFDVR_FWD_BINDING_VIEWS 2  // RenderView per view
#define TFM_DIFFDVR_FWD_BINDING_STATE 3  // vec4 per pixel per view: C.rgb, T
#define TFM_DIFFDVR_FWD_BINDING_STOP 4   // uint per pixel per view: samples marched (k_stop)

// ---- diffdvr_backward.comp ------------------------------------------------------------------
// One invocation per pixel of the field being optimized: loss against the target pixel, then the
// re-march k = k_stop-1 .. 0 inverting the compositing. 16x16 tiles: 256 rays share one flush
// of the workgroup's accumulators.
#define TFM_DIFFDVR_BACKWARD_TILE 16
#define TFM_DIFFDVR_BWD_BINDING_FIELD 0   // float chunks [TFM_RENDER_MAX_CHUNKS]
#define TFM_DIFFDVR_BWD_BINDING_TF 1      // vec4 TF entries (the TF being optimized)
#define TFM_DIFFDVR_BWD_BINDING_VIEWS 2   // RenderView per view
#define TFM_DIFFDVR_BWD_BINDING_STATE 3   // forward state (C, T) per pixel per view
#define TFM_DIFFDVR_BWD_BINDING_STOP 4    // k_stop per pixel per view
#define TFM_DIFFDVR_BWD_BINDING_TARGET 5  // target image, forward state layout (C, T)
#define TFM_DIFFDVR_BWD_BINDING_ACCUM 6   // TFM_DIFFDVR_SLOTS(n) accumulators, 2 uints each

// Specialization constants: workgroup x, y (TFM_SPEC_WORKGROUP_X/Y, both
// TFM_DIFFDVR_BACKWARD_TILE), field chunks (TFM_RENDER_SPEC_CHUNKS), then these.
#define TFM_DIFFDVR_SPEC_LOSS 3          // TFM_DIFFDVR_LOSS_*
#define TFM_DIFFDVR_SPEC_SHARED_WORDS 4  // words of workgroup-shared accumulators (2 per slot)
#define TFM_DIFFDVR_SPEC_USE_SHARED 5    // 0: add straight to the global accumulators (large N)
#define TFM_DIFFDVR_LOSS_L2 0u           // sum over RGBA of (X - R)^2
#define TFM_DIFFDVR_LOSS_L1 1u           // sum over RGBA of |X - R|

// Accumulators, each a 64-bit 32.32 fixed-point number as two uints (low word first):
//   slot 4j + c (j < n, c < 4): dLoss/dT_o[j][c] of the SUM loss, signed (two's complement);
//   slot 4n: the loss itself (non-negative).
// Integer addition modulo 2^64 is exact and associative, so the totals have the same bits
// whatever the scheduling, and a negative term is added like any other.
#define TFM_DIFFDVR_SLOTS(n) (4u * (n) + 1u)

#endif  // TFMATCH_DIFFDVR_LAYOUT_H

// GLSL helpers that need raymarch.glsl's types: a shader includes this header once before its
// bindings (for the macros above) and once more after raymarch.glsl (for these).
#if !defined(__cplusplus) && defined(TFMATCH_RAYMARCH_GLSL) && !defined(TFMATCH_DIFFDVR_HELPERS)
#define TFMATCH_DIFFDVR_HELPERS
// The marching constants of the render push block, filled as render_image.comp fills them.
MarchParams march_params_from_push() {
  MarchParams mp;
  mp.dims = uvec3(rp.dim_x, rp.dim_y, rp.dim_z);
  mp.chunk_voxels = rp.chunk_voxels;
  mp.inv_axis = vec3(rp.inv_axis_x, rp.inv_axis_y, rp.inv_axis_z);
  mp.dt = rp.dt;
  mp.depth_per_alpha = rp.depth_per_alpha;
  mp.stop_transmittance = rp.stop_transmittance;
  mp.max_steps = rp.max_steps;
  mp.tf_lo = rp.tf_lo;
  mp.tf_scale = rp.tf_scale;
  mp.tf_size = rp.tf_size;
  return mp;
}

// The ray of `pixel` seen from camera `v` (steps = 0 on a miss).
Ray view_ray(RenderView v, uvec2 pixel, MarchParams mp) {
  Ray ray;
  setup_ray(v.eye.xyz, v.forward.xyz, v.right.xyz, v.up.xyz, v.eye.w, v.forward.w, pixel,
            uvec2(rp.width, rp.height), mp, ray);
  return ray;
}
#endif
