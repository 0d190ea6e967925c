// Direct volume rendering of one field with one TF from one or more cameras: per pixel the
// premultiplied RGBA before any background, and the number of samples marched (for DiffDVR).
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_RENDER_PUSH
#include "render_layout.h"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X, local_size_y_id = TFM_SPEC_WORKGROUP_Y) in;
layout(constant_id = TFM_RENDER_SPEC_MODE) const uint MODE = TFM_RENDER_MODE_FORWARD;

TFM_DECLARE_RAYMARCH_BINDINGS(TFM_RENDER_BINDING_FIELD, TFM_RENDER_BINDING_TF)
#include "raymarch.glsl"

layout(std430, binding = TFM_RENDER_BINDING_VIEWS) readonly buffer Views { RenderView views[]; };
layout(std430, binding = TFM_RENDER_BINDING_IMAGE) writeonly buffer Image { vec4 image[]; };
layout(std430, binding = TFM_RENDER_BINDING_STOP) writeonly buffer Stop { uint stop_index[]; };

void main() {
  const uvec2 pixel = uvec2(gl_GlobalInvocationID.x, gl_GlobalInvocationID.y + rp.row_offset);
  const uint view = gl_GlobalInvocationID.z;
  if (pixel.x >= rp.width || pixel.y >= rp.height || view >= rp.view_count) return;

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

  const RenderView v = views[view];
  Ray ray;
  setup_ray(v.eye.xyz, v.forward.xyz, v.right.xyz, v.up.xyz, v.eye.w, v.forward.w, pixel,
            uvec2(rp.width, rp.height), mp, ray);
  vec3 color;
  float transmittance;
  const uint k_stop = march_forward(ray, mp, color, transmittance);

  if (MODE == TFM_RENDER_MODE_INVERSE_CHECK) {
    // Walk back exactly as a DiffDVR backward pass would; the state must return to (0, 1).
    for (uint k = k_stop; k > 0u; --k) {
      vec3 rgb;
      float tau;
      if (shade_sample(ray, k - 1u, mp, rgb, tau)) uncomposite(color, transmittance, rgb, tau);
    }
  }
  const uint index = (view * rp.height + pixel.y) * rp.width + pixel.x;
  image[index] = vec4(color, 1.0 - transmittance);
  stop_index[index] = k_stop;
}
