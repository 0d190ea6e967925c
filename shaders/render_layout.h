// Interface of the direct volume renderer (also the DiffDVR forward pass, one of its modes) and
// the residual-map kernel, shared by GLSL and C++: bindings, workgroup sizes,
// specialization-constant ids, the per-view camera record and the push-constant block. Only
// 4-byte scalars and vec4s, so std430 and C++ layouts coincide (kernels/render_image.cpp and
// kernels/residual_map.cpp static_assert the sizes).
#ifndef TFMATCH_RENDER_LAYOUT_H
#define TFMATCH_RENDER_LAYOUT_H

#include "shared_layout.h"

#ifdef __cplusplus
#define TFM_RENDER_VEC4(name) float name[4]
#define TFM_RENDER_STRUCT(Name) struct Name
namespace tfm::gpu {
#else
#define TFM_RENDER_VEC4(name) vec4 name
#define TFM_RENDER_STRUCT(Name) struct Name
#endif

// ---- render_image.comp ----------------------------------------------------------------------
// One invocation per pixel, 8x8 tiles; gl_GlobalInvocationID.z selects the view (camera), so a
// DiffDVR pass can render several cameras of one field in one dispatch.
#define TFM_RENDER_TILE 8
// Field chunks an array binding holds (chunks are <= maxStorageBufferRange each: 8 x 128 MiB on
// lavapipe, i.e. up to 2^28 float voxels). Unused slots repeat the last chunk.
#define TFM_RENDER_MAX_CHUNKS 8
#define TFM_RENDER_BINDING_FIELD 0   // float chunks [TFM_RENDER_MAX_CHUNKS]
#define TFM_RENDER_BINDING_TF 1      // vec4 TF entries
#define TFM_RENDER_BINDING_VIEWS 2   // RenderView per view
#define TFM_RENDER_BINDING_IMAGE 3   // vec4 per pixel per view: as TFM_RENDER_MODE_* says
#define TFM_RENDER_BINDING_STOP 4    // uint per pixel per view: samples marched (k_stop)
// Specialization constants: workgroup x, y (TFM_SPEC_WORKGROUP_X/Y, both TFM_RENDER_TILE), then
// these. Every marching kernel (render_image, diffdvr_backward) declares TFM_RENDER_SPEC_CHUNKS.
#define TFM_RENDER_SPEC_CHUNKS 2  // chunks of the field (1..TFM_RENDER_MAX_CHUNKS)
#define TFM_RENDER_SPEC_MODE 3    // TFM_RENDER_MODE_*
// The image: per pixel (premultiplied colour C, opacity 1 - T).
#define TFM_RENDER_MODE_FORWARD 0u
// Forward, then re-march k = k_stop-1 .. 0 inverting each compositing step (what DiffDVR's
// backward pass does) and write the recovered start state (colour, 1 - transmittance), which
// must be ~0: a self-check that forward and backward see identical samples.
#define TFM_RENDER_MODE_INVERSE_CHECK 1u
// The DiffDVR forward pass: the same march, but the state written per pixel is (C, T), the
// transmittance itself. The backward pass divides T by each sample's tau, so it needs T exactly;
// 1 - (1 - T) in float loses it (to 0 when T < 6e-8).
#define TFM_RENDER_MODE_DIFFDVR_STATE 2u

// Optical depth of one sample is clamped here so a sample's transmittance exp(-depth) stays a
// normal float far from 0 (exp(-20) = 2e-9): the backward pass divides by it. The clamp
// changes alpha by < 2.1e-9, below float resolution near 1.
#define TFM_MAX_SAMPLE_OPTICAL_DEPTH 20.0

// A pinhole camera in world units (voxel index space scaled by spacing / finest spacing).
TFM_RENDER_STRUCT(RenderView) {
  TFM_RENDER_VEC4(eye);      // xyz: position; w: tan(vertical fov / 2)
  TFM_RENDER_VEC4(forward);  // xyz: unit view direction; w: aspect (width / height)
  TFM_RENDER_VEC4(right);    // xyz: unit image +x
  TFM_RENDER_VEC4(up);       // xyz: unit image +y (image rows run top to bottom)
};

#ifndef __cplusplus
// The bindings shaders/raymarch.glsl expects (declare before including it): the field's chunks
// as texel buffers, or in the TFM_FIELD_IMAGE variant (the recording path reading a host's 3D
// image in place) one sampled 3D image whose texel (x, y, z) is voxel (x, y, z); and the TF.
#ifdef TFM_FIELD_IMAGE
#define TFM_DECLARE_RAYMARCH_FIELD(field_binding) layout(binding = field_binding) uniform texture3D field_image;
#else
#define TFM_DECLARE_RAYMARCH_FIELD(field_binding) \
  layout(binding = field_binding) uniform samplerBuffer field_chunks[TFM_RENDER_MAX_CHUNKS];
#endif
#define TFM_DECLARE_RAYMARCH_BINDINGS(field_binding, tf_binding)                                 \
  layout(constant_id = TFM_RENDER_SPEC_CHUNKS) const uint FIELD_CHUNKS = 1u;                     \
  TFM_DECLARE_RAYMARCH_FIELD(field_binding)                                                      \
  layout(binding = tf_binding) uniform samplerBuffer tf_table;
#endif

#ifdef __cplusplus
// The pipeline interface of render_image.comp in any mode (RenderImageKernel, and
// DiffDvrForwardKernel in TFM_RENDER_MODE_DIFFDVR_STATE). Its wrappers dispatch the buffers in
// this order: field chunks, TF, views, image, stop.
inline constexpr auto kRenderBindingCounts =
    binding_counts({TFM_RENDER_BINDING_FIELD, TFM_RENDER_BINDING_TF, TFM_RENDER_BINDING_VIEWS, TFM_RENDER_BINDING_IMAGE,
                    TFM_RENDER_BINDING_STOP},
                   TFM_RENDER_BINDING_FIELD, TFM_RENDER_MAX_CHUNKS);
inline std::vector<uint> render_specialization(uint field_chunks, uint mode) {
  return by_id({{TFM_SPEC_WORKGROUP_X, TFM_RENDER_TILE},
                {TFM_SPEC_WORKGROUP_Y, TFM_RENDER_TILE},
                {TFM_RENDER_SPEC_CHUNKS, field_chunks},
                {TFM_RENDER_SPEC_MODE, mode}});
}
#endif

#if defined(__cplusplus) || defined(TFM_WANT_RENDER_PUSH)
TFM_PUSH_CONSTANTS(RenderPush) {
  uint width;             // image size in pixels
  uint height;
  uint row_offset;        // rows [row_offset, row_end) of the image are this dispatch's (renders
  uint row_end;           // and backward passes may be split in bands)
  uint view_count;
  uint dim_x;             // grid size
  uint dim_y;
  uint dim_z;
  uint chunk_voxels;      // voxels per field chunk (all but the last)
  uint tf_size;
  float tf_lo;            // field mapping of tf_common.glsl
  float tf_scale;
  float dt;               // step between samples, world units
  float depth_per_alpha;  // optical depth of one step for TF opacity 1: opacity_scale * dt / box length
  float stop_transmittance;  // 1 - termination opacity: stop once transmittance <= this
  uint max_steps;         // samples per ray never exceed this (box diagonal / dt + 1)
  float inv_axis_x;       // world -> index: index = world * inv_axis
  float inv_axis_y;
  float inv_axis_z;
  // render_image: this dispatch marches samples [first_sample, sample_end) of each ray, resuming
  // from the state an earlier dispatch stored when first_sample > 0; sample_end 0: to the ray's
  // end. Long rays come in several dispatches where the driver limits an invocation's loops
  // (kernels/render_image.cpp); the other marching kernels take whole rays (0, 0).
  uint first_sample;
  uint sample_end;
} TFM_PUSH_INSTANCE(rp);
#endif

// ---- residual_map.comp ----------------------------------------------------------------------
// 1-D over one range of a chunk's voxels (first_voxel, voxel_count), push constants:
// VoxelPairPush (shared_layout.h), whose `opt_*` fields describe the second field and its TF.
// Bindings: both fields as storage buffers (the range's last count % 4 voxels) and as uniform
// texel buffers of RGBA32F quads over the range, both TFs as texels, the output chunk as floats
// (the tail) and as vec4 quads. Specialization: workgroup size only.
#define TFM_RESIDUAL_BINDING_REF_FIELD 0
#define TFM_RESIDUAL_BINDING_OPT_FIELD 1
#define TFM_RESIDUAL_BINDING_REF_TF 2
#define TFM_RESIDUAL_BINDING_OPT_TF 3
#define TFM_RESIDUAL_BINDING_OUT 4
#define TFM_RESIDUAL_BINDING_REF_QUADS 5
#define TFM_RESIDUAL_BINDING_OPT_QUADS 6
#define TFM_RESIDUAL_BINDING_OUT_QUADS 7
// The variant that reads both fields from 3D images (TFM_FIELD_IMAGE, field_image.glsl): their x
// and y sizes (every field binding then holds a sampled image).
#define TFM_RESIDUAL_SPEC_IMAGE_NX 1
#define TFM_RESIDUAL_SPEC_IMAGE_NY 2

#ifdef __cplusplus
}  // namespace tfm::gpu
#endif
#endif  // TFMATCH_RENDER_LAYOUT_H
