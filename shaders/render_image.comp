// Direct volume rendering of one field with one TF from one or more cameras (z = view): per pixel
// the premultiplied RGBA before any background and the samples marched k_stop. Also the DiffDVR
// forward pass (TFM_RENDER_MODE_DIFFDVR_STATE), which differs only in what it stores per pixel.
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
  uvec2 pixel;
  uint view;
  if (!invocation_pixel(pixel, view)) return;
  const MarchParams mp = march_params_from_push();
  const Ray ray = view_ray(views[view], pixel, mp);
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
  const uint index = pixel_index(pixel, view);
  image[index] = vec4(color, MODE == TFM_RENDER_MODE_DIFFDVR_STATE ? transmittance : 1.0 - transmittance);
  stop_index[index] = k_stop;
}
