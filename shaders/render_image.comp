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
// Read back when a dispatch resumes the rays an earlier one began (rp.first_sample > 0).
layout(std430, binding = TFM_RENDER_BINDING_IMAGE) buffer Image { vec4 image[]; };
layout(std430, binding = TFM_RENDER_BINDING_STOP) buffer Stop { uint stop_index[]; };

void main() {
  uvec2 pixel;
  uint view;
  if (!invocation_pixel(pixel, view)) return;
  const MarchParams mp = march_params_from_push();
  const Ray ray = view_ray(views[view], pixel, mp);
  const uint index = pixel_index(pixel, view);
  vec3 color = vec3(0.0);
  float transmittance = 1.0;
  uint k = 0u;
  if (rp.first_sample > 0u) {
    // A later part of a long ray: the state where the earlier dispatch left it, unless the ray
    // ended there (its last sample, or early termination).
    k = stop_index[index];
    const vec4 state = image[index];
    color = state.rgb;
    transmittance = MODE == TFM_RENDER_MODE_DIFFDVR_STATE ? state.a : 1.0 - state.a;
    if (k < rp.first_sample || k >= ray.steps || transmittance <= mp.stop_transmittance) return;
  }
  const uint k_stop = march_forward(ray, mp, k, rp.sample_end == 0u ? ray.steps : rp.sample_end, color, transmittance);

  if (MODE == TFM_RENDER_MODE_INVERSE_CHECK) {
    // Walk back exactly as a DiffDVR backward pass would; the state must return to (0, 1).
    for (uint back = k_stop; back > 0u; --back) {
      vec3 rgb;
      float tau;
      if (shade_sample(ray, back - 1u, mp, rgb, tau)) uncomposite(color, transmittance, rgb, tau);
    }
  }
  image[index] = vec4(color, MODE == TFM_RENDER_MODE_DIFFDVR_STATE ? transmittance : 1.0 - transmittance);
  stop_index[index] = k_stop;
}
