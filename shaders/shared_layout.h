// One source of truth for kernel interfaces: included by GLSL compute shaders and by C++ wrappers.
// Push-constant blocks use only 4-byte scalars so that std430 and C++ layouts coincide; the C++
// side static_asserts their sizes (kernels/*.cpp).
#ifndef TFMATCH_SHARED_LAYOUT_H
#define TFMATCH_SHARED_LAYOUT_H

#ifdef __cplusplus
#include <cstdint>
namespace tfm::gpu {
using uint = std::uint32_t;
#define TFM_PUSH_CONSTANTS(Name) struct Name
#define TFM_PUSH_INSTANCE(instance)
#else
#define TFM_PUSH_CONSTANTS(Name) layout(push_constant, std430) uniform Name
#define TFM_PUSH_INSTANCE(instance) instance
#endif

// Default workgroup size of the 1-D voxel kernels (specialization constant 0 may lower it).
#define TFM_VOXEL_WORKGROUP 256

// Fixed-point accumulators: a 64-bit unsigned 32.32 number kept as two 32-bit words
// (low word first). Only core 32-bit atomics are needed, and integer addition is associative,
// so sums are bit-identical whatever the scheduling.
#define TFM_FIXED_ONE 4294967296.0

// ---- assemble_normal_equations.comp -------------------------------------------------------
// Accumulator slots (each two uints): M diagonal [0, N), M super-diagonal [N, 2N-1),
// S^T b as [2N-1 + 4j + c], b^T b per channel [6N-1 + c], voxel count [6N+3].
#define TFM_ASSEMBLE_BINDING_REF_FIELD 0
#define TFM_ASSEMBLE_BINDING_OPT_FIELD 1
#define TFM_ASSEMBLE_BINDING_REF_TF 2
#define TFM_ASSEMBLE_BINDING_ACCUM 3
#define TFM_ASSEMBLE_SLOTS(n) (6u * (n) + 4u)
// Contiguous voxels one invocation accumulates in registers before touching shared memory.
#define TFM_ASSEMBLE_RUN 16u

// Push constants of the kernels that map a pair of fields (reference, optimized) through TFs:
// assemble_normal_equations and voxel_loss. A shader opts in with TFM_WANT_VOXEL_PAIR_PUSH
// (GLSL allows one push-constant block per shader; other kernels have their own layout headers).
#if defined(__cplusplus) || defined(TFM_WANT_VOXEL_PAIR_PUSH)
TFM_PUSH_CONSTANTS(VoxelPairPush) {
  uint voxel_count;   // voxels in this chunk
  uint opt_tf_size;   // N, entries of the TF being optimized
  uint ref_tf_size;   // entries of the reference TF
  uint pad0;
  float ref_lo;       // reference field mapping: x = clamp((v - lo) * scale, 0, size-1)
  float ref_scale;
  float opt_lo;
  float opt_scale;
} TFM_PUSH_INSTANCE(pc);
#endif

// ---- voxel_loss.comp ----------------------------------------------------------------------
// Accumulator slots: sum of squared difference per channel [0,4), sum of absolute difference
// per channel [4,8), voxel count [8].
#define TFM_LOSS_BINDING_REF_FIELD 0
#define TFM_LOSS_BINDING_OPT_FIELD 1
#define TFM_LOSS_BINDING_REF_TF 2
#define TFM_LOSS_BINDING_OPT_TF 3
#define TFM_LOSS_BINDING_ACCUM 4
#define TFM_LOSS_SLOTS 9u

#ifdef __cplusplus
// How a field maps to TF coordinates in float32, as tf_coordinate() of tf_common.glsl computes it:
// x = clamp((v - lo) * scale, 0, tf_size - 1), scale = (tf_size - 1) / (hi - lo) rounded to float
// (host/core/field_mapping.h makes one from a range and mirrors the arithmetic bit for bit).
struct FieldMapping {
  float lo = 0.0f;
  float scale = 1.0f;
  uint tf_size = 2;
};
}  // namespace tfm::gpu
namespace tfm {
using gpu::FieldMapping;
}  // namespace tfm
#endif
#endif  // TFMATCH_SHARED_LAYOUT_H
