// DiffDVR forward pass: one field, one TF, a batch of cameras (gl_GlobalInvocationID.z = view).
// Per pixel only the final state (premultiplied colour C, transmittance T) and the samples
// marched k_stop: what the backward pass starts from. Same march as render_image.comp
// (march_forward of raymarch.glsl, same push block), so its opacity 1 - T is the renderer's.
#version 450
#extension GL_GOOGLE_include_directive : require
#define TFM_WANT_RENDER_PUSH
#include "diffdvr_layout.h"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X, local_size_y_id = TFM_SPEC_WORKGROUP_Y) in;

TFM_DECLARE_RAYMARCH_BINDINGS(TFM_DIFFDVR_FWD_BINDING_FIELD, TFM_DIFFDVR_FWD_BINDING_TF)
#include "raymarch.glsl"
#include "diffdvr_layout.h"

layout(std430, binding = TFM_DIFFDVR_FWD_BINDING_VIEWS) readonly buffer Views { RenderView views[]; };
layout(std430, binding = TFM_DIFFDVR_FWD_BINDING_STATE) writeonly buffer State { vec4 state[]; };
layout(std430, binding = TFM_DIFFDVR_FWD_BINDING_STOP) writeonly buffer Stop { uint stop_index[]; };

void main() {
  const uvec2 pixel = uvec2(gl_GlobalInvocationID.x, gl_GlobalInvocationID.y + rp.row_offset);
  const uint view = gl_GlobalInvocationID.z;
  if (pixel.x >= rp.width || pixel.y >= rp.height || view >= rp.view_count) return;
  const MarchParams mp = march_params_from_push();
  const Ray ray = view_ray(views[view], pixel, mp);
  vec3 color;
  float transmittance;
  const uint k_stop = march_forward(ray, mp, color, transmittance);
  const uint index = (view * rp.height + pixel.y) * rp.width + pixel.x;
  state[index] = vec4(color, transmittance);
  stop_index[index] = k_stop;
}
