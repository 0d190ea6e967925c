// How the voxel kernels walk a dispatch's quads of voxels (assemble_normal_equations, gd_gradient,
// sparse_scatter, field_pair_read): subgroups take segments of TFM_REDUCE_SEGMENT_STEPS quads per
// lane, grid-stride over the dispatch; in each step a subgroup's lanes are on consecutive quads, so
// every step reads one contiguous span, and each subgroup streams through its own part of the
// range. TFM_FOR_EACH_QUAD(q, quads) { ... } runs its body for this lane's quads q of [0, quads).
// Needs GL_KHR_shader_subgroup_basic and shared_layout.h.
#ifndef TFMATCH_QUAD_SEGMENTS_GLSL
#define TFMATCH_QUAD_SEGMENTS_GLSL

#define TFM_FOR_EACH_QUAD(q, quads)                                                                   \
  for (uint tfm_s = gl_WorkGroupID.x * gl_NumSubgroups + gl_SubgroupID,                               \
            tfm_segment = gl_SubgroupSize * TFM_REDUCE_SEGMENT_STEPS;                                 \
       tfm_s * tfm_segment < (quads); tfm_s += gl_NumWorkGroups.x * gl_NumSubgroups)                  \
    for (uint q = tfm_s * tfm_segment + gl_SubgroupInvocationID,                                      \
              tfm_end = min(tfm_s * tfm_segment + tfm_segment, (quads));                              \
         q < tfm_end; q += gl_SubgroupSize)

#endif  // TFMATCH_QUAD_SEGMENTS_GLSL
