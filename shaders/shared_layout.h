// One source of truth for kernel interfaces: included by GLSL compute shaders and by C++ wrappers.
// Push-constant blocks use only 4-byte scalars so that std430 and C++ layouts coincide; the C++
// side static_asserts their sizes (kernels/*.cpp).
#ifndef TFMATCH_SHARED_LAYOUT_H
#define TFMATCH_SHARED_LAYOUT_H

#ifdef __cplusplus
#include <array>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>
namespace tfm::gpu {
using uint = std::uint32_t;
#define TFM_PUSH_CONSTANTS(Name) struct Name
#define TFM_PUSH_INSTANCE(instance)
#else
#define TFM_PUSH_CONSTANTS(Name) layout(push_constant, std430) uniform Name
#define TFM_PUSH_INSTANCE(instance) instance
#endif

// Specialization ids of the workgroup size in every kernel (layout(local_size_x_id = ...)).
#define TFM_SPEC_WORKGROUP_X 0
#define TFM_SPEC_WORKGROUP_Y 1

// Workgroup size of the 1-D voxel kernels.
#define TFM_VOXEL_WORKGROUP 256

// Where the voxel-reducing kernels (assemble_normal_equations, sparse_scatter, gd_gradient) sum
// their terms: the value of their MODE specialization constant (kernels/reduction.h).
#define TFM_REDUCE_RUNS_SHARED 0u  // register runs, flushed to workgroup-shared accumulators
#define TFM_REDUCE_RUNS_GLOBAL 1u  // register runs, flushed to the global accumulators
#define TFM_REDUCE_PRIVATE 2u      // a private histogram per lane, added to memory at the end
// The most quads a lane takes from one contiguous segment of its subgroup, one per step
// (quad_segments.glsl: fewer where the dispatch has more lanes than that needs).
#define TFM_REDUCE_SEGMENT_STEPS 64u

// Fixed-point accumulators (shaders/fixed_point.glsl): each slot is one 64-bit 32.32 number kept
// as two 32-bit words (low word first), unsigned or two's complement. Only core 32-bit atomics
// are needed, and integer addition is associative, so sums are bit-identical whatever the
// scheduling.
#define TFM_FIXED_ONE 4294967296.0
#define TFM_FIXED_SLOT_WORDS 2u

#ifdef __cplusplus
inline constexpr std::uint64_t kFixedSlotBytes = TFM_FIXED_SLOT_WORDS * sizeof(uint);

// The engine takes descriptor counts and specialization values as lists indexed by binding
// number and constant_id, and a dispatch's buffers in binding order. These helpers let a wrapper
// name every position instead of relying on the order of a brace list.

// Descriptor counts of bindings 0..n-1, given by name in binding order (the order in which the
// wrapper lists its buffers at dispatch): one buffer each, `array_count` for `array_binding`.
// Throws std::logic_error when the names are not 0, 1, ..., n-1; evaluated into a constexpr
// variable, such a list does not compile.
template <std::size_t N>
constexpr std::array<uint, N> binding_counts(const uint (&ids)[N], uint array_binding = ~0u, uint array_count = 1u) {
  std::array<uint, N> counts{};
  for (std::size_t i = 0; i < N; ++i) {
    if (ids[i] != i) throw std::logic_error("bindings are not listed in binding order");
    counts[i] = ids[i] == array_binding ? array_count : 1u;
  }
  return counts;
}

template <std::size_t N>
std::vector<uint> to_vector(const std::array<uint, N>& a) {
  return {a.begin(), a.end()};
}

// Specialization values indexed by constant_id from (id, value) pairs. Ids missing from the list
// get 0 (Vulkan ignores map entries of ids a shader does not declare). Throws std::logic_error
// when an id is given twice.
template <typename Pairs>
std::vector<uint> by_id_of(const Pairs& values) {
  std::vector<uint> out;
  std::vector<bool> set;
  for (const auto& [id, value] : values) {
    if (id >= out.size()) {
      out.resize(id + 1, 0u);
      set.resize(id + 1, false);
    }
    if (set[id]) throw std::logic_error("specialization constant " + std::to_string(id) + " given twice");
    out[id] = value;
    set[id] = true;
  }
  return out;
}
inline std::vector<uint> by_id(std::initializer_list<std::pair<uint, uint>> values) { return by_id_of(values); }
inline std::vector<uint> by_id(const std::vector<std::pair<uint, uint>>& values) { return by_id_of(values); }
#endif

// ---- assemble_normal_equations.comp (and its TFM_INT64 variant) ----------------------------
// Accumulator slots (unsigned): M diagonal [0, N), M super-diagonal [N, 2N-1),
// S^T b as [2N-1 + 4j + c], b^T b per channel [6N-1 + c], voxel count [6N+3], and, with the
// specialization WITH_BEFORE, the "before" loss per channel [6N+4 + c]: the sum of
// (T_r(F_o) - b)^2 with the second field mapped onto the reference TF (before_lo, before_scale).
// The loss of the optimized TF's size follows from M; this one is of another TF size.
// Bindings: the fields' chunks as storage buffers (float[], for the last voxel_count % 4 voxels)
// and as RGBA32F texel buffers over the dispatch's range (quads), the reference TF as RGBA32F
// texels, the accumulators.
#define TFM_ASSEMBLE_BINDING_REF_FIELD 0
#define TFM_ASSEMBLE_BINDING_OPT_FIELD 1
#define TFM_ASSEMBLE_BINDING_REF_TF 2
#define TFM_ASSEMBLE_BINDING_ACCUM 3
#define TFM_ASSEMBLE_BINDING_REF_QUADS 4
#define TFM_ASSEMBLE_BINDING_OPT_QUADS 5
// The TFM_WEIGHTED variant (visibility-weighted least squares): per-voxel weights as a third
// field, one voxel a texel and the range's quads as RGBA texels, multiplying every term.
#define TFM_ASSEMBLE_BINDING_WEIGHTS 6
#define TFM_ASSEMBLE_BINDING_WEIGHT_QUADS 7
#define TFM_ASSEMBLE_SLOTS(n) (6u * (n) + 8u)
// Specialization: workgroup size (TFM_SPEC_WORKGROUP_X), then these.
#define TFM_ASSEMBLE_SPEC_MODE 1          // TFM_REDUCE_RUNS_SHARED, _RUNS_GLOBAL or _PRIVATE
#define TFM_ASSEMBLE_SPEC_SHARED_SLOTS 2  // slots of workgroup-shared accumulators (RUNS_SHARED)
#define TFM_ASSEMBLE_SPEC_PRIVATE_BINS 3  // TF entries of each lane's private histogram (PRIVATE)
#define TFM_ASSEMBLE_SPEC_TERM_FIRST 4    // first of the 11 bin terms workgroup row 0 adds (row y: + y TERM_COUNT)
#define TFM_ASSEMBLE_SPEC_TERM_COUNT 5    // bin terms a row adds (11 but in PRIVATE passes: a row per pass)
#define TFM_ASSEMBLE_SPEC_WITH_BEFORE 6   // 1: also sum the before loss (push: before_lo, before_scale)
// The variant that reads both fields from 3D images (TFM_FIELD_IMAGE): their x and y sizes, to
// turn a voxel index into a texel (every field binding then holds a sampled image).
#define TFM_ASSEMBLE_SPEC_IMAGE_NX 7
#define TFM_ASSEMBLE_SPEC_IMAGE_NY 8

// Push constants of the kernels that map a pair of fields (reference, optimized) through TFs:
// assemble_normal_equations and voxel_loss. A shader opts in with TFM_WANT_VOXEL_PAIR_PUSH
// (GLSL allows one push-constant block per shader; other kernels have their own layout headers).
#if defined(__cplusplus) || defined(TFM_WANT_VOXEL_PAIR_PUSH)
TFM_PUSH_CONSTANTS(VoxelPairPush) {
  uint voxel_count;   // voxels in this dispatch's range
  uint opt_tf_size;   // N, entries of the TF being optimized
  uint ref_tf_size;   // entries of the reference TF
  uint first_voxel;   // the range's first voxel in the bound chunk (assembly: its quads start there)
  float ref_lo;       // reference field mapping: x = clamp((v - lo) * scale, 0, size-1)
  float ref_scale;
  float opt_lo;
  float opt_scale;
  float before_lo;    // WITH_BEFORE (assembly, voxel loss): the second field mapped onto the
  float before_scale; // reference TF's entries
} TFM_PUSH_INSTANCE(pc);
#endif

// ---- voxel_loss.comp ----------------------------------------------------------------------
// Bindings: both fields as storage buffers (the range's last count % 4 voxels) and as uniform
// texel buffers of RGBA32F quads over the dispatch's range, both TFs as texels, the accumulators.
// Accumulator slots (unsigned) of one loss: sum of squared difference per channel [0,4), sum of
// absolute difference per channel [4,8), voxel count [8]; with WITH_BEFORE the loss before
// optimization follows in [9,18).
#define TFM_LOSS_BINDING_REF_FIELD 0
#define TFM_LOSS_BINDING_OPT_FIELD 1
#define TFM_LOSS_BINDING_REF_TF 2
#define TFM_LOSS_BINDING_OPT_TF 3
#define TFM_LOSS_BINDING_ACCUM 4
#define TFM_LOSS_BINDING_REF_QUADS 5
#define TFM_LOSS_BINDING_OPT_QUADS 6
#define TFM_LOSS_SLOTS 9u
// Specialization: workgroup size (TFM_SPEC_WORKGROUP_X), then this.
#define TFM_LOSS_SPEC_WITH_BEFORE 1  // 1: also the before loss (push: before_lo, before_scale)
#define TFM_LOSS_SPEC_IMAGE_NX 2     // TFM_FIELD_IMAGE variant: the images' x and y sizes
#define TFM_LOSS_SPEC_IMAGE_NY 3

#ifdef __cplusplus
// How a field maps to TF coordinates in float32, as tf_coordinate() of tf_common.glsl computes it:
// x = clamp((v - lo) * scale, 0, tf_size - 1), scale = (tf_size - 1) / (hi - lo) rounded to float
// (host/model/field_mapping.h makes one from a range and mirrors the arithmetic bit for bit).
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
