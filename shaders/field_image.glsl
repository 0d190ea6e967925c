// Fields held in a host's 3D images (the TFM_FIELD_IMAGE variants of the voxel kernels: the
// recording path reads a renderer's volumes in place). Voxel i of the volume is texel
// (i mod IMAGE_NX, i / IMAGE_NX mod IMAGE_NY, i / (IMAGE_NX IMAGE_NY)), fetched by index without a
// sampler: R32F, R16F, R16 or R8 unorm give the float the buffer formats give. The including
// shader declares the specialization constants IMAGE_NX and IMAGE_NY first.
#ifndef TFMATCH_FIELD_IMAGE_GLSL
#define TFMATCH_FIELD_IMAGE_GLSL
#extension GL_EXT_samplerless_texture_functions : require

ivec3 image_texel(uint i) { return ivec3(i % IMAGE_NX, (i / IMAGE_NX) % IMAGE_NY, i / (IMAGE_NX * IMAGE_NY)); }

// Voxel i, and the four voxels from voxel `first`, of the image.
#define IMAGE_VOXEL(image, i) texelFetch(image, image_texel(i), 0).x
#define IMAGE_QUAD(image, first)                                                                     \
  vec4(IMAGE_VOXEL(image, (first)), IMAGE_VOXEL(image, (first) + 1u), IMAGE_VOXEL(image, (first) + 2u), \
       IMAGE_VOXEL(image, (first) + 3u))

#endif  // TFMATCH_FIELD_IMAGE_GLSL
