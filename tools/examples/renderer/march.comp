// The example renderer's own kernel: one invocation per pixel marches its column of the volume
// front to back (an orthographic view down z), the TF read from the renderer's TF buffer with the
// convention of tfmatch's DESIGN.md (linear interpolation between N entries, opacity as
// extinction), and writes an RGBA8 pixel. The volume is a 3D image read by texel fetch without a
// sampler: R32_SFLOAT gives the float, R16_UNORM the code c as c / 65535 (lo and scale map those).
#version 450
#extension GL_EXT_samplerless_texture_functions : require
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0) uniform texture3D volume;
layout(std430, binding = 1) readonly buffer Tf { vec4 tf[]; };
layout(std430, binding = 2) writeonly buffer Pixels { uint pixels[]; };
layout(push_constant) uniform Push {
  uint nx, ny, nz, tf_size;
  float lo, scale, extinction;
  uint size;  // the image is size x size pixels
} p;

void main() {
  const uvec2 px = gl_GlobalInvocationID.xy;
  if (px.x >= p.size || px.y >= p.size) return;
  const uint x = px.x * p.nx / p.size, y = px.y * p.ny / p.size;
  vec3 colour = vec3(0.0);
  float transmittance = 1.0;
  for (uint z = 0; z < p.nz && transmittance > 0.01; ++z) {
    const float v = texelFetch(volume, ivec3(x, y, z), 0).r;
    if (isnan(v)) continue;
    const float t = clamp((v - p.lo) * p.scale, 0.0, float(p.tf_size - 1u));
    const uint j = min(uint(floor(t)), p.tf_size - 2u);
    const vec4 e = mix(tf[j], tf[j + 1u], t - float(j));
    const float alpha = 1.0 - exp(-e.a * p.extinction);
    colour += transmittance * alpha * e.rgb;
    transmittance *= 1.0 - alpha;
  }
  pixels[px.y * p.size + px.x] = packUnorm4x8(vec4(colour, 1.0 - transmittance));
}
