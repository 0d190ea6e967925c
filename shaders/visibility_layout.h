// Interface of visibility_weights.comp (kernels/visibility_weights.h), shared by GLSL and C++:
// bindings, specialization ids, modes and the push block. 4-byte scalars only, so std430 and C++
// layouts coincide (kernels/visibility_weights.cpp static_asserts the size).
#ifndef TFMATCH_VISIBILITY_LAYOUT_H
#define TFMATCH_VISIBILITY_LAYOUT_H

#include "render_layout.h"  // RenderView, the ray-march bindings and chunk count

#ifdef __cplusplus
namespace tfm::gpu {
#endif

// 1-D over a range of voxels inside one chunk of the weight field.
#define TFM_VIS_BINDING_FIELD 0  // the reference field's chunks [TFM_RENDER_MAX_CHUNKS] (texels)
#define TFM_VIS_BINDING_TF 1     // the reference TF, RGBA32F texels
#define TFM_VIS_BINDING_VIEWS 2  // RenderView per camera
#define TFM_VIS_BINDING_OUT 3    // the weight field's chunk holding the range, float per voxel
#define TFM_VIS_BINDING_MAX 4    // one uint: the bits of the largest sum (atomicMax)
#define TFM_VIS_BINDING_PARTIAL 5  // rays in parts: the chunk of a float per voxel, the transmittance
                                   // of the view's ray where the part before left it
// Specialization: workgroup size (TFM_SPEC_WORKGROUP_X), the field's chunk count
// (TFM_RENDER_SPEC_CHUNKS, as every marching kernel), then the mode.
#define TFM_VIS_SPEC_MODE 3
// Adds the views [view_first, view_first + view_count) to each voxel's sum (the first batch of
// views writes it); with `finish`, also takes the maximum over the voxels.
#define TFM_VIS_MODE_SUM 0u
// Replaces each sum w by round(2^16 w / max) 2^-16.
#define TFM_VIS_MODE_QUANTIZE 1u
// A transmittance below this ends the march as 0 (2^-24).
#define TFM_VIS_MIN_TRANSMITTANCE 5.9604645e-8

TFM_PUSH_CONSTANTS(VisibilityPush) {
  uint dim_x;             // grid size
  uint dim_y;
  uint dim_z;
  uint chunk_voxels;      // voxels per chunk of the reference field (all but the last)
  uint first_voxel;       // this dispatch's voxels [first_voxel, first_voxel + voxel_count) of the grid
  uint voxel_count;
  uint out_first;         // the grid index of the bound weight chunk's first voxel
  uint view_first;        // the views of this dispatch (MODE_SUM)
  uint view_count;
  uint finish;            // 1: the last batch of views: take the maximum too
  uint tf_size;           // the reference TF and its mapping (tf_common.glsl)
  float tf_lo;
  float tf_scale;
  float dt;               // the renderer's step, world units
  float depth_per_alpha;  // optical depth of one step at TF opacity 1
  float stop_transmittance;  // the renderer's (not used: see visibility_weights.comp)
  uint max_steps;
  float inv_axis_x;       // world -> index: index = world * inv_axis
  float inv_axis_y;
  float inv_axis_z;
  // Samples (first_sample, sample_end] of one view's rays, when they are marched in parts
  // (march_parts: devices that limit an invocation's loops); 0, 0: whole rays.
  uint sample_first;
  uint sample_end;
} TFM_PUSH_INSTANCE(vp);

#ifdef __cplusplus
}  // namespace tfm::gpu
#endif

#endif  // TFMATCH_VISIBILITY_LAYOUT_H
