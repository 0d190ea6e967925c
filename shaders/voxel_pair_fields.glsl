// The two fields of a voxel-pair kernel (assemble_normal_equations, residual_map, voxel_loss) and
// how it reads them: REF_VOXEL(i) and OPT_VOXEL(i), voxel i of the chunk; REF_QUAD(q) and
// OPT_QUAD(q), the four voxels of quad q of the dispatch's range (from pc.first_voxel). Either
// texel buffers in the field's storage format (a float, a float16, a unorm: the fetch gives the
// float), one voxel a texel and the range's quads as RGBA texels; or, in the TFM_FIELD_IMAGE
// variants, two of a host's 3D images read in place (field_image.glsl), every field binding
// holding one. The includer defines the bindings TFM_FIELDS_REF, TFM_FIELDS_OPT,
// TFM_FIELDS_REF_QUADS, TFM_FIELDS_OPT_QUADS and the specialization ids TFM_FIELDS_SPEC_NX,
// TFM_FIELDS_SPEC_NY (the images' x and y sizes) first, and declares `pc` with first_voxel.
#ifndef TFMATCH_VOXEL_PAIR_FIELDS_GLSL
#define TFMATCH_VOXEL_PAIR_FIELDS_GLSL

#ifdef TFM_FIELD_IMAGE
layout(constant_id = TFM_FIELDS_SPEC_NX) const uint IMAGE_NX = 1u;
layout(constant_id = TFM_FIELDS_SPEC_NY) const uint IMAGE_NY = 1u;
#include "field_image.glsl"
layout(binding = TFM_FIELDS_REF) uniform texture3D ref_image;
layout(binding = TFM_FIELDS_OPT) uniform texture3D opt_image;
#define REF_VOXEL(i) IMAGE_VOXEL(ref_image, i)
#define OPT_VOXEL(i) IMAGE_VOXEL(opt_image, i)
#define REF_QUAD(q) IMAGE_QUAD(ref_image, pc.first_voxel + 4u * (q))
#define OPT_QUAD(q) IMAGE_QUAD(opt_image, pc.first_voxel + 4u * (q))
#else
layout(binding = TFM_FIELDS_REF) uniform samplerBuffer ref_field;  // one voxel a texel
layout(binding = TFM_FIELDS_OPT) uniform samplerBuffer opt_field;
layout(binding = TFM_FIELDS_REF_QUADS) uniform samplerBuffer ref_quads;
layout(binding = TFM_FIELDS_OPT_QUADS) uniform samplerBuffer opt_quads;
#define REF_VOXEL(i) texelFetch(ref_field, int(i)).x
#define OPT_VOXEL(i) texelFetch(opt_field, int(i)).x
#define REF_QUAD(q) texelFetch(ref_quads, int(q))
#define OPT_QUAD(q) texelFetch(opt_quads, int(q))
#endif

#endif  // TFMATCH_VOXEL_PAIR_FIELDS_GLSL
