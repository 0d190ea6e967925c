// Interface of shaders/field_pair_read.comp, shared by GLSL and kernels/read_bound.cpp: bindings
// and the push-constant block (4-byte scalars only, so std430 and C++ layouts coincide).
#ifndef TFMATCH_READ_BOUND_LAYOUT_H
#define TFMATCH_READ_BOUND_LAYOUT_H

#include "shared_layout.h"

#ifdef __cplusplus
namespace tfm::gpu {
#endif

#define TFM_READ_BINDING_REF_FIELD 0  // float: the chunk of the first field (its last count % 4 voxels)
#define TFM_READ_BINDING_OPT_FIELD 1  // float: the same chunk of the second field
#define TFM_READ_BINDING_REF_QUADS 2  // uniform texel buffer, RGBA32F: the range's quads of the first
#define TFM_READ_BINDING_OPT_QUADS 3  // the same of the second
#define TFM_READ_BINDING_RESULT 4     // uint[2]: the sums of the two fields' value bits, added to

#if defined(__cplusplus) || defined(TFM_WANT_READ_BOUND_PUSH)
TFM_PUSH_CONSTANTS(ReadBoundPush) {
  uint voxel_count;  // voxels of this dispatch's range
  uint first_voxel;  // the range's first voxel within the chunk
} TFM_PUSH_INSTANCE(pc);
#endif

#ifdef __cplusplus
}  // namespace tfm::gpu
#endif

#endif  // TFMATCH_READ_BOUND_LAYOUT_H
