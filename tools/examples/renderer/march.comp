// The example renderer's own kernel: one invocation per pixel marches its column of the volume
// front to back (an orthographic view down z), the TF read from the renderer's TF buffer with the
// convention of tfmatch's DESIGN.md (linear interpolation between N entries, opacity as
// extinction), and writes an RGBA8 pixel. A volume is float32 or unorm16 codes.
#version 450
layout(local_size_x = 8, local_size_y = 8) in;
layout(std430, binding = 0) readonly buffer Volume { uint words[]; };  // floats, or unorm16 codes two a word
layout(std430, binding = 1) readonly buffer Tf { vec4 tf[]; };
layout(std430, binding = 2) writeonly buffer Pixels { uint pixels[]; };
layout(push_constant) uniform Push {
  uint nx, ny, nz, tf_size;
  float lo, scale, extinction;
  uint size;     // the image is size x size pixels
  uint unorm16;  // 1: the volume holds unorm16 codes, read as c / 65535 (lo and scale map those)
} p;

float voxel(uint i) {
  if (p.unorm16 == 0u) return uintBitsToFloat(words[i]);
  const uint w = words[i >> 1];
  return float((i & 1u) != 0u ? w >> 16 : w & 0xffffu) / 65535.0;
}

void main() {
  const uvec2 px = gl_GlobalInvocationID.xy;
  if (px.x >= p.size || px.y >= p.size) return;
  const uint x = px.x * p.nx / p.size, y = px.y * p.ny / p.size;
  vec3 colour = vec3(0.0);
  float transmittance = 1.0;
  for (uint z = 0; z < p.nz && transmittance > 0.01; ++z) {
    const float v = voxel((z * p.ny + y) * p.nx + x);
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
