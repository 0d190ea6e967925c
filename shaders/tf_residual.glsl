// The residual of the voxel objective at a TF x, shared by gd_gradient and irls_assemble: per
// voxel e = T_o(F_o) - b with T_o = x (the iterate, kept in [0,1] by its solver) and
// b = T_r(F_r) clamped to [0,1]. The including shader declares the specialization constants
// PRIVATE_BINS (N on CPU devices, where each lane copies x, else 0) and TF_CACHE_ENTRIES (the
// reference TF's entries copied per lane, or 0), the buffers ref_tf[] and x[] (N RGBA entries)
// and the push block pc (VoxelPairPush), includes tf_common.glsl, and calls residual_begin()
// once per invocation.
#ifndef TFMATCH_TF_RESIDUAL_GLSL
#define TFMATCH_TF_RESIDUAL_GLSL

// Private copies of the two TFs (CPU devices: gathers from private memory are cheap there).
vec4 ref_cache[TF_CACHE_ENTRIES + 1u];
vec4 x_cache[PRIVATE_BINS + 1u];
vec4 ref_entry(uint j) { return TF_CACHE_ENTRIES > 0u ? ref_cache[j] : ref_tf[j]; }
vec4 x_entry(uint j) { return PRIVATE_BINS > 0u ? x_cache[j] : x[j]; }

void residual_begin() {
  for (uint j = 0u; j < TF_CACHE_ENTRIES; ++j) ref_cache[j] = ref_tf[j];
  for (uint j = 0u; j < PRIVATE_BINS; ++j) x_cache[j] = x[j];
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
