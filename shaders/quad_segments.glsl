// How the voxel kernels walk a dispatch's quads of voxels (assemble_normal_equations, gd_gradient,
// sparse_scatter, field_pair_read and the other voxel passes): subgroups take segments of S quads
// per lane, grid-stride over the dispatch; in each step a subgroup's lanes are on consecutive
// quads, so every step reads one contiguous span, and each subgroup streams through its own part
// of the range. S is the dispatch's quads over its lanes, rounded up, at most
// TFM_REDUCE_SEGMENT_STEPS: so the host's workgroup count alone says how the range spreads (every
// launched subgroup gets a segment while the range has one for it; with a fixed S of 64, a
// dispatch sized for 16 quads per lane left three subgroups in four without work), and lanes of
// more than 64 quads take several segments. The integer sums of every kernel do not depend on the
// walk. TFM_FOR_EACH_QUAD(q, quads) { ... } runs its body for this lane's quads q of [0, quads).
// Needs GL_KHR_shader_subgroup_basic and shared_layout.h.
#ifndef TFMATCH_QUAD_SEGMENTS_GLSL
#define TFMATCH_QUAD_SEGMENTS_GLSL

// S above: uniform over the dispatch (quads is).
uint tfm_segment_steps(uint quads) {
  const uint lanes = gl_NumWorkGroups.x * gl_NumSubgroups * gl_SubgroupSize;
  return clamp((quads + lanes - 1u) / lanes, 1u, TFM_REDUCE_SEGMENT_STEPS);
}

#define TFM_FOR_EACH_QUAD(q, quads)                                                                   \
  for (uint tfm_s = gl_WorkGroupID.x * gl_NumSubgroups + gl_SubgroupID,                               \
            tfm_segment = gl_SubgroupSize * tfm_segment_steps(quads);                                 \
       tfm_s * tfm_segment < (quads); tfm_s += gl_NumWorkGroups.x * gl_NumSubgroups)                  \
    for (uint q = tfm_s * tfm_segment + gl_SubgroupInvocationID,                                      \
              tfm_end = min(tfm_s * tfm_segment + tfm_segment, (quads));                              \
         q < tfm_end; q += gl_SubgroupSize)

#endif  // TFMATCH_QUAD_SEGMENTS_GLSL
