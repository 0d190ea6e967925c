// Interface of the DiffDVR backward kernel (diffdvr_backward.comp), shared by GLSL and C++:
// bindings, tile, specialization-constant ids and the gradient accumulator layout. The forward
// pass is render_image.comp in TFM_RENDER_MODE_DIFFDVR_STATE (render_layout.h); both take the
// renderer's push block (RenderPush, filled by make_render_push) and camera records, so they march
// exactly the renderer's rays and samples.
#ifndef TFMATCH_DIFFDVR_LAYOUT_H
#define TFMATCH_DIFFDVR_LAYOUT_H

#include "render_layout.h"

// ---- diffdvr_backward.comp ------------------------------------------------------------------
// One invocation per pixel of the field being optimized (the private build: per
// TFM_DIFFDVR_PRIVATE_PIXELS pixels): loss against the target pixel, then the re-march
// k = k_stop-1 .. 0 inverting the compositing. 16x16 tiles: 256 rays share one flush of the
// workgroup's accumulators; a private workgroup covers 16 x (16 TFM_DIFFDVR_PRIVATE_PIXELS).
#define TFM_DIFFDVR_BACKWARD_TILE 16
#define TFM_DIFFDVR_PRIVATE_PIXELS 4
#define TFM_DIFFDVR_BWD_BINDING_FIELD 0   // float chunks [TFM_RENDER_MAX_CHUNKS]
#define TFM_DIFFDVR_BWD_BINDING_TF 1      // vec4 TF entries (the TF being optimized)
#define TFM_DIFFDVR_BWD_BINDING_VIEWS 2   // RenderView per view
#define TFM_DIFFDVR_BWD_BINDING_STATE 3   // forward state (C, T) per pixel per view
#define TFM_DIFFDVR_BWD_BINDING_STOP 4    // k_stop per pixel per view
#define TFM_DIFFDVR_BWD_BINDING_TARGET 5  // target image, forward state layout (C, T)
#define TFM_DIFFDVR_BWD_BINDING_ACCUM 6   // TFM_DIFFDVR_SLOTS(n) accumulators, 2 uints each
#define TFM_DIFFDVR_BWD_BINDING_RESUME 7  // runs build, rays in parts: 2 vec4 per pixel per view, the
                                          // state (C, T) and its adjoints where the part before left them

// Specialization constants: workgroup x, y (TFM_SPEC_WORKGROUP_X/Y, both
// TFM_DIFFDVR_BACKWARD_TILE), field chunks (TFM_RENDER_SPEC_CHUNKS), then these.
#define TFM_DIFFDVR_SPEC_LOSS 3          // TFM_DIFFDVR_LOSS_*
#define TFM_DIFFDVR_SPEC_SHARED_WORDS 4  // words of workgroup-shared accumulators (2 per slot)
#define TFM_DIFFDVR_SPEC_USE_SHARED 5    // 0: add straight to the global accumulators (large N)
#define TFM_DIFFDVR_SPEC_PRIVATE_BINS 6  // TFM_DIFFDVR_PRIVATE build: entries of a lane's histogram
#define TFM_DIFFDVR_SPEC_PIXELS_PER_LANE 7  // TFM_DIFFDVR_PRIVATE build: pixels each lane marches
#define TFM_DIFFDVR_SPEC_FLAT_RUNS 8  // default build: 1 marches the runs in one loop (devices with a loop limit)
#define TFM_DIFFDVR_LOSS_L2 0u           // sum over RGBA of (X - R)^2
#define TFM_DIFFDVR_LOSS_L1 1u           // sum over RGBA of |X - R|

// Accumulators, each a 32.32 fixed-point slot of shaders/fixed_point.glsl (two uints):
//   slot 4j + c (j < n, c < 4): dLoss/dT_o[j][c] of the SUM loss, signed (two's complement);
//   slot 4n: the loss itself (non-negative).
#define TFM_DIFFDVR_SLOTS(n) (4u * (n) + 1u)

#endif  // TFMATCH_DIFFDVR_LAYOUT_H
