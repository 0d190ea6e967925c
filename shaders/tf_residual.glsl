// The residual of the voxel objective at a TF x, shared by gd_gradient and irls_assemble: per
// voxel e = T_o(F_o) - b with T_o = x (the iterate, kept in [0,1] by its solver) and
// b = T_r(F_r) clamped to [0,1]. The including shader declares the specialization constants
// PRIVATE_BINS (N on CPU devices, where each lane copies x, else 0) and TF_CACHE_ENTRIES (the
// reference TF's entries copied per lane, or 0), the buffers ref_tf[] and x[] (N RGBA entries)
// and the push block pc (VoxelPairPush), includes tf_common.glsl, and calls residual_begin()
// once per invocation.
#ifndef TFMATCH_TF_RESIDUAL_GLSL
#define TFMATCH_TF_RESIDUAL_GLSL

// Private copies of the two TFs (CPU devices: gathers from private memory are cheap there), one
// array per channel: lavapipe's compile time grows faster than linearly with a private array's
// size (assemble_normal_equations.comp), so four arrays of N floats beat one of N vec4s.
float ref_cache_r[TF_CACHE_ENTRIES + 1u], ref_cache_g[TF_CACHE_ENTRIES + 1u];
float ref_cache_b[TF_CACHE_ENTRIES + 1u], ref_cache_a[TF_CACHE_ENTRIES + 1u];
float x_cache_r[PRIVATE_BINS + 1u], x_cache_g[PRIVATE_BINS + 1u];
float x_cache_b[PRIVATE_BINS + 1u], x_cache_a[PRIVATE_BINS + 1u];
vec4 ref_entry(uint j) {
  return TF_CACHE_ENTRIES > 0u ? vec4(ref_cache_r[j], ref_cache_g[j], ref_cache_b[j], ref_cache_a[j]) : ref_tf[j];
}
vec4 x_entry(uint j) { return PRIVATE_BINS > 0u ? vec4(x_cache_r[j], x_cache_g[j], x_cache_b[j], x_cache_a[j]) : x[j]; }

void residual_begin() {
  for (uint j = 0u; j < TF_CACHE_ENTRIES; ++j) {
    const vec4 v = ref_tf[j];
    ref_cache_r[j] = v.r, ref_cache_g[j] = v.g, ref_cache_b[j] = v.b, ref_cache_a[j] = v.a;
  }
  for (uint j = 0u; j < PRIVATE_BINS; ++j) {
    const vec4 v = x[j];
    x_cache_r[j] = v.r, x_cache_g[j] = v.g, x_cache_b[j] = v.b, x_cache_a[j] = v.a;
  }
}

// The voxel's optimized-TF coordinate (entry j, weight t towards j + 1), b and e; false, with
// e = 0, when either field has no data there.
bool voxel_residual(float ref_value, float opt_value, out uint j, out float t, out vec4 b, out vec4 e) {
  uint jr;
  float wr;
  const bool ref_ok = tf_coordinate(ref_value, pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr);
  const bool ok = tf_coordinate(opt_value, pc.opt_lo, pc.opt_scale, pc.opt_tf_size, j, t) && ref_ok;
  b = clamp((1.0 - wr) * ref_entry(jr) + wr * ref_entry(jr + 1u), 0.0, 1.0);
  e = ok ? (1.0 - t) * x_entry(j) + t * x_entry(j + 1u) - b : vec4(0.0);
  return ok;
}

#endif
