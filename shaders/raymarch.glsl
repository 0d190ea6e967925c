// The emission-absorption ray marching of DESIGN.md, in pieces that a forward renderer and a
// DiffDVR backward pass share, so both see bit-identical samples:
//   setup_ray()         pixel -> ray entry point, direction and sample count K in the volume box
//   sample_position()   sample k (0 <= k < K) at t_k = t_entry + (k + 0.5) dt, from the entry point
//   sample_field()      trilinear over a chunked field; false when any corner is NaN (empty)
//   classify()          node-aligned TF lookup (tf_coordinate of tf_common.glsl), j and w exposed
//   sample_transmittance()  tau = exp(-min(a * depth_per_alpha, max)): alpha = 1 - tau
//   composite() / uncomposite()  one front-to-back step and its exact inverse
// State along a ray is premultiplied colour C and transmittance T = 1 - opacity:
//   C += T (1 - tau) c,  T *= tau.
// Inverse (the "inversion trick"): T /= tau, C -= T (1 - tau) c. It needs tau > 0, which the
// optical-depth clamp guarantees, and T > 0 at the stop, which early termination at an opacity
// below 1 guarantees (T >= (1 - threshold) * tau_min when the ray stops). So a backward pass
// re-marches k = k_stop-1 .. 0 from the final (C, T) without storing per-sample data.
//
// Every pixel-marching kernel takes the renderer's push block and cameras, and marches through
//   march_params_from_push(), view_ray()  the rays of RenderPush `rp` and a RenderView
//   invocation_pixel(), pixel_index()     which pixel of which view an invocation handles
// so renderer, DiffDVR forward and backward pass trace the same rays with the same constants
// (those define TFM_WANT_RENDER_PUSH before including render_layout.h, for the push block `rp`;
// a kernel without it, such as visibility_weights.comp, fills MarchParams itself).
//
// The including shader declares, before including this file:
//   layout(constant_id = TFM_RENDER_SPEC_CHUNKS) const uint FIELD_CHUNKS;
//   texel-buffer array `field_chunks[TFM_RENDER_MAX_CHUNKS]` (R32F views of the chunks), or in
//   the TFM_FIELD_IMAGE variant the 3D image `field_image`
//   texel buffer `tf_table` (RGBA32F entries)
// Texel buffers, not storage buffers: on CPU devices (lavapipe) a texel fetch is one vector gather
// where a storage-buffer load with a per-lane index loops over the SIMD lanes (see
// assemble_normal_equations.comp); GPUs read both at the same speed.
// (TFM_DECLARE_RAYMARCH_BINDINGS of render_layout.h declares exactly these.)
#ifndef TFMATCH_RAYMARCH_GLSL
#define TFMATCH_RAYMARCH_GLSL

#include "tf_common.glsl"

// Everything marching needs besides the camera, filled once per dispatch.
struct MarchParams {
  uvec3 dims;
  uint chunk_voxels;
  vec3 inv_axis;          // world -> index scale per axis
  float dt;               // world units
  float depth_per_alpha;  // optical depth of one step at TF opacity 1
  float stop_transmittance;
  uint max_steps;
  float tf_lo;
  float tf_scale;
  uint tf_size;
};

// A ray in voxel index space: sample k lies at entry + (k + 0.5) * dt * dir.
struct Ray {
  vec3 entry;   // index-space point where the ray enters the box [-0.5, dims - 0.5]
  vec3 dir;     // index-space displacement per world unit
  uint steps;   // K = round((t_exit - t_entry) / dt), at most max_steps
  float depth_per_alpha;  // optical depth of one of its steps at TF opacity 1
};

// Pixel (x, y), y = 0 at the top, through its centre. Returns false (steps = 0) on a miss.
bool setup_ray(vec3 eye, vec3 forward, vec3 right, vec3 up, float tan_half_fov, float aspect,
               uvec2 pixel, uvec2 size, MarchParams mp, out Ray ray) {
  const float sx = ((2.0 * (float(pixel.x) + 0.5)) / float(size.x) - 1.0) * tan_half_fov * aspect;
  const float sy = (1.0 - (2.0 * (float(pixel.y) + 0.5)) / float(size.y)) * tan_half_fov;
  const vec3 dir_world = normalize(forward + sx * right + sy * up);
  const vec3 o = eye * mp.inv_axis;
  const vec3 d = dir_world * mp.inv_axis;
  const vec3 box_hi = vec3(mp.dims) - 0.5;
  float t0 = 0.0;  // the camera may sit inside the box: start at the eye then
  float t1 = 3.0e38;
  for (int a = 0; a < 3; ++a) {
    // An explicit branch, not 1/0 = inf: GLSL leaves division by zero unspecified.
    if (abs(d[a]) < 1e-30) {
      if (o[a] < -0.5 || o[a] > box_hi[a]) t1 = -1.0;
    } else {
      const float ta = (-0.5 - o[a]) / d[a];
      const float tb = (box_hi[a] - o[a]) / d[a];
      t0 = max(t0, min(ta, tb));
      t1 = min(t1, max(ta, tb));
    }
  }
  ray.entry = o + t0 * d;
  ray.dir = d;
  ray.steps = 0u;
  ray.depth_per_alpha = mp.depth_per_alpha;
  if (!(t1 > t0)) return false;
  const float count = floor((t1 - t0) / mp.dt + 0.5);
  ray.steps = uint(min(count, float(mp.max_steps)));
  // The K samples share the chord's optical length: each weighs (t_exit - t_entry) / K, not dt,
  // so a ray's optical depth follows its chord smoothly. Weighted by dt it jumped by a step where
  // K did (by 1/K: rings on a thin slab seen from above, where K is 4 to 6). The samples stay at
  // (k + 0.5) dt (K dt is the chord to within dt / 2). A ray cut at max_steps keeps dt.
  if (count >= 1.0 && count <= float(mp.max_steps))
    ray.depth_per_alpha = mp.depth_per_alpha * ((t1 - t0) / (count * mp.dt));
  return ray.steps > 0u;
}

// The marching constants of a push block that carries them under their names (RenderPush,
// VisibilityPush; the host fills them from one make_render_push).
#define TFM_MARCH_PARAMS_OF(p) \
  MarchParams(uvec3(p.dim_x, p.dim_y, p.dim_z), p.chunk_voxels, vec3(p.inv_axis_x, p.inv_axis_y, p.inv_axis_z), \
              p.dt, p.depth_per_alpha, p.stop_transmittance, p.max_steps, p.tf_lo, p.tf_scale, p.tf_size)

#ifdef TFM_WANT_RENDER_PUSH
// The marching constants of the render push block (make_render_push fills it on the host).
MarchParams march_params_from_push() { return TFM_MARCH_PARAMS_OF(rp); }

// The ray of `pixel` seen from camera `v` (steps = 0 on a miss).
Ray view_ray(RenderView v, uvec2 pixel, MarchParams mp) {
  Ray ray;
  setup_ray(v.eye.xyz, v.forward.xyz, v.right.xyz, v.up.xyz, v.eye.w, v.forward.w, pixel,
            uvec2(rp.width, rp.height), mp, ray);
  return ray;
}

// Pixel `pixel` of view `view` if it is in the image, the dispatch's rows and the views.
bool pixel_in_dispatch(uvec2 pixel, uint view) {
  return pixel.x < rp.width && pixel.y < rp.row_end && view < rp.view_count;
}

// The pixel and view of this invocation: x, y (offset by the dispatch's first row) and z of the
// global id. False past the image, the dispatch's rows or the views.
bool invocation_pixel(out uvec2 pixel, out uint view) {
  pixel = uvec2(gl_GlobalInvocationID.x, gl_GlobalInvocationID.y + rp.row_offset);
  view = gl_GlobalInvocationID.z;
  return pixel_in_dispatch(pixel, view);
}

// Index of a pixel of a view in the per-pixel buffers (image, state, stop, target).
uint pixel_index(uvec2 pixel, uint view) { return (view * rp.height + pixel.y) * rp.width + pixel.x; }
#endif  // TFM_WANT_RENDER_PUSH

vec3 sample_position(Ray ray, uint k, float dt) {
  return ray.entry + ((float(k) + 0.5) * dt) * ray.dir;
}

#ifdef TFM_FIELD_IMAGE
#extension GL_EXT_samplerless_texture_functions : require
// Voxel (x, y, z) of the host's 3D image, fetched without a sampler.
float field_voxel(uvec3 at, MarchParams mp) { return texelFetch(field_image, ivec3(at), 0).x; }
#else
// One voxel of a chunked field. Every descriptor index is a constant (indexing an array of texel
// buffers with a variable, even a uniform one, needs a device feature); chunks the
// specialization does not have fold away, and with one chunk it is a plain fetch.
float fetch_voxel(uint i, uint chunk_voxels) {
  if (FIELD_CHUNKS == 1u) return texelFetch(field_chunks[0], int(i)).x;
  const uint c = i / chunk_voxels;
  const int off = int(i - c * chunk_voxels);
  float value = 0.0;
#if TFM_RENDER_MAX_CHUNKS != 8
#error "fetch_voxel lists TFM_RENDER_MAX_CHUNKS chunks"
#endif
#define TFM_FETCH_CHUNK(k) if (FIELD_CHUNKS > uint(k) && c == uint(k)) value = texelFetch(field_chunks[k], off).x;
  TFM_FETCH_CHUNK(0) TFM_FETCH_CHUNK(1) TFM_FETCH_CHUNK(2) TFM_FETCH_CHUNK(3)
  TFM_FETCH_CHUNK(4) TFM_FETCH_CHUNK(5) TFM_FETCH_CHUNK(6) TFM_FETCH_CHUNK(7)
#undef TFM_FETCH_CHUNK
  return value;
}

// Voxel (x, y, z) of the chunked field.
float field_voxel(uvec3 at, MarchParams mp) {
  return fetch_voxel(at.z * (mp.dims.x * mp.dims.y) + at.y * mp.dims.x + at.x, mp.chunk_voxels);
}
#endif

// Trilinear interpolation between voxel centres (at integer index coordinates), clamped to the
// edge voxels. Returns false when any of the 8 corners has no data (NaN, ±Inf): such samples are
// empty.
bool sample_field(vec3 p, MarchParams mp, out float value) {
  const vec3 top = vec3(mp.dims - 1u);
  const vec3 q = clamp(p, vec3(0.0), top);
  const vec3 f = floor(q);
  const vec3 w = q - f;
  const uvec3 i0 = uvec3(f);
  const uvec3 i1 = min(i0 + 1u, mp.dims - 1u);
  const float c000 = field_voxel(uvec3(i0.x, i0.y, i0.z), mp);
  const float c100 = field_voxel(uvec3(i1.x, i0.y, i0.z), mp);
  const float c010 = field_voxel(uvec3(i0.x, i1.y, i0.z), mp);
  const float c110 = field_voxel(uvec3(i1.x, i1.y, i0.z), mp);
  const float c001 = field_voxel(uvec3(i0.x, i0.y, i1.z), mp);
  const float c101 = field_voxel(uvec3(i1.x, i0.y, i1.z), mp);
  const float c011 = field_voxel(uvec3(i0.x, i1.y, i1.z), mp);
  const float c111 = field_voxel(uvec3(i1.x, i1.y, i1.z), mp);
  value = 0.0;
  // The eight corners as two vec4 tests (eight scalar no_data() tests cost llvmpipe's renderer
  // about 10 % of its samples per second; these cost none measurable).
  if (any(no_data4(vec4(c000, c100, c010, c110))) || any(no_data4(vec4(c001, c101, c011, c111)))) return false;
  const float x00 = mix(c000, c100, w.x), x10 = mix(c010, c110, w.x);
  const float x01 = mix(c001, c101, w.x), x11 = mix(c011, c111, w.x);
  value = mix(mix(x00, x10, w.y), mix(x01, x11, w.y), w.z);
  return true;
}

// T(v) of the node-aligned TF; j, w are the entries and weight a gradient pass scatters to:
// d rgba / d T_j = 1 - w, d rgba / d T_{j+1} = w.
vec4 classify(float value, MarchParams mp, out uint j, out float w) {
  tf_coordinate(value, mp.tf_lo, mp.tf_scale, mp.tf_size, j, w);
  return (1.0 - w) * texelFetch(tf_table, int(j)) + w * texelFetch(tf_table, int(j + 1u));
}

// Transmittance of one step of `ray` for TF opacity a (alpha = 1 - tau).
float sample_transmittance(float a, Ray ray) {
  return exp(-min(a * ray.depth_per_alpha, TFM_MAX_SAMPLE_OPTICAL_DEPTH));
}

void composite(inout vec3 color, inout float transmittance, vec3 rgb, float tau) {
  color += (transmittance * (1.0 - tau)) * rgb;
  transmittance *= tau;
}

void uncomposite(inout vec3 color, inout float transmittance, vec3 rgb, float tau) {
  transmittance /= tau;
  color -= (transmittance * (1.0 - tau)) * rgb;
}

// Sample k of a ray classified: false when empty (NaN). rgba.a is the TF opacity, tau the
// step's transmittance.
bool shade_sample(Ray ray, uint k, MarchParams mp, out vec3 rgb, out float tau) {
  float value;
  rgb = vec3(0.0);
  tau = 1.0;
  if (!sample_field(sample_position(ray, k, mp.dt), mp, value)) return false;
  uint j;
  float w;
  const vec4 c = clamp(classify(value, mp, j, w), 0.0, 1.0);
  rgb = c.rgb;
  tau = sample_transmittance(c.a, ray);
  return true;
}

// Front-to-back marching with early termination from sample k (color/transmittance hold the state
// before it: (0, 1) at k = 0) up to sample k_end. Returns the samples marched (k_stop: the ray
// stopped after sample k_stop - 1); color/transmittance hold the final state.
uint march_forward(Ray ray, MarchParams mp, uint k, uint k_end, inout vec3 color, inout float transmittance) {
  k_end = min(k_end, ray.steps);
  while (k < k_end) {
    vec3 rgb;
    float tau;
    if (shade_sample(ray, k, mp, rgb, tau)) composite(color, transmittance, rgb, tau);
    ++k;
    if (transmittance <= mp.stop_transmittance) break;
  }
  return k;
}

#endif
