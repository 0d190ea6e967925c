// The voxel walk of the tf_residual.glsl kernels (gd_gradient, irls_assemble): this lane's quads
// of the dispatch in segments (quad_segments.glsl), then the last voxel_count % 4 voxels by the
// first invocation, each voxel handed to take(ref_value, opt_value), which the including shader
// defines before including this file along with the texel bindings ref_quads, opt_quads (RGBA32F
// quads of voxels) and ref_field, opt_field (one voxel a texel).
#ifndef TFMATCH_TF_RESIDUAL_WALK_GLSL
#define TFMATCH_TF_RESIDUAL_WALK_GLSL

void residual_walk() {
  const uint quads = pc.voxel_count / 4u;
  TFM_FOR_EACH_QUAD(q, quads) {
    const vec4 rv = texelFetch(ref_quads, int(q));
    const vec4 ov = texelFetch(opt_quads, int(q));
    // A loop, not four calls: each inlined take() carries its reduction's run flush, and four
    // copies made lavapipe compile irls_assemble (24 slots a flush) several times slower. It makes
    // a quad cost TFM_RESIDUAL_WALK_LOOPS_PER_QUAD loop iterations (the host sizes lanes by it).
    for (uint k = 0u; k < 4u; ++k) take(rv[k], ov[k]);
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint i = 4u * quads; i < pc.voxel_count; ++i) take(texelFetch(ref_field, int(i)).x, texelFetch(opt_field, int(i)).x);
}

#endif
