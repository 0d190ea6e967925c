// Interface of the correlation-field kernels (shaders/correlation_*.comp), shared by GLSL and
// kernels/correlation.cpp: bindings, specialization ids, strategy sizes and the push-constant
// block (4-byte scalars only, so std430 and C++ layouts coincide; the wrapper static_asserts it).
#ifndef TFMATCH_CORRELATION_LAYOUT_H
#define TFMATCH_CORRELATION_LAYOUT_H

#include "shared_layout.h"

#ifdef __cplusplus
namespace tfm::gpu {
#endif

// Every correlation kernel has the same six bindings (a kernel ignores those its measure does
// not need; the wrapper binds a small placeholder there).
#define TFM_CORR_BINDING_ENSEMBLE 0    // float: one chunk of the ensemble, layout per strategy (below)
#define TFM_CORR_BINDING_OUT 1         // float per voxel of the chunk
#define TFM_CORR_BINDING_REF_VALUES 2  // float texels: the reference series as the measure needs it
#define TFM_CORR_BINDING_REF_ORDER 3   // uint per position in x order (x = reference): its member
#define TFM_CORR_BINDING_REF_GROUP 4   // uint per position in x order: first position of its x tie group
#define TFM_CORR_BINDING_TABLE 5       // float per count c = 0..M: ln(c) (mi-binned) or digamma(c) (mi-kraskov)

// Specialization: workgroup size (TFM_SPEC_WORKGROUP_X, a power of two), then these.
#define TFM_CORR_SPEC_GROUP_PER_VOXEL 1  // 0: one invocation per voxel; 1: one workgroup per voxel
#define TFM_CORR_SPEC_REGION_FLOATS 2    // floats of one shared-memory region (see below)
#define TFM_CORR_SPEC_SHARED_FLOATS 3    // floats of all regions (regions * REGION_FLOATS, at least 1)
#define TFM_CORR_SPEC_COEFFICIENT 4      // mi-kraskov: write sqrt(1 - exp(-2 max(MI, 0))) instead of MI
#define TFM_CORR_SPEC_MEMBER_MAJOR 5     // 1: series member-major (stride member_stride); 0: voxel-major

// Strategies (why: the header comment of shaders/correlation_common.glsl).
// One invocation per voxel: the chunk is member-major (value of member m at voxel v at
// m * voxel_count + v), so neighbouring invocations read neighbouring addresses. Kernels that
// keep the series keep it in a slice of workgroup-shared memory of TFM_CORR_SLICE_STRIDE floats
// per invocation and region (stride 33, not 32: slices of neighbours start in different banks).
#define TFM_CORR_INVOCATION_MAX_MEMBERS 32u
#define TFM_CORR_INVOCATION_WORKGROUP 64u
#define TFM_CORR_SLICE_STRIDE 33u
// One workgroup per voxel: the chunk is voxel-major (member m of voxel v at v * M + m), so a
// workgroup reads its series at consecutive addresses. A region holds the series of one voxel:
// M rounded up to a multiple of TFM_CORR_CAPACITY_STEP floats (fewer pipelines than one per M).
#define TFM_CORR_CAPACITY_STEP 64u
// 32 invocations (a warp; half a wave on older AMD parts) share a voxel's work: the merge levels
// below a tile of ceil(M / 32) values run without barriers, and barriers are what a workgroup per
// voxel pays for on lavapipe (its invocations switch contexts at each). mi-kraskov takes more
// when one invocation's neighbour walks could exceed the loop budget.
#define TFM_CORR_GROUP_WORKGROUP 32u
// Loop iterations one invocation may run for one voxel: half of llvmpipe's 65535, after which it
// silently ends every loop of the invocation.
#define TFM_CORR_LOOP_BUDGET 32768u

// Spearman and Kendall compare every pair of members up to these many (with one workgroup per
// voxel M^2 / T comparisons an invocation, no sort and none of its barriers), and merge-sort
// beyond. Measured on lavapipe (bench-correlate, voxels/s, pairs against merge sort): spearman
// 2.35x at M = 10, 1.36x at 32 (one invocation per voxel), 2.2x at 48, 1.5x at 96, 1.0x at 128,
// 0.92x at 200; kendall (three comparisons a pair) 1.65x at 10, 1.11x at 32, 1.5x at 48, 1.25x
// at 64, 0.83x at 96, 0.47x at 200. Not measured on a GPU yet.
#define TFM_CORR_SPEARMAN_PAIRS_MAX_MEMBERS 128u
#define TFM_CORR_KENDALL_PAIRS_MAX_MEMBERS 64u

// Pearson takes one pass over a voxel's members, its sums shifted by the first member, while
// M (mean - y0)^2 <= this many times the series' sum of squared deviations, and a second pass
// about the mean beyond (shaders/correlation_pearson.comp; the error bound depends on it).
#define TFM_CORR_PEARSON_SHIFT_LIMIT 16.0

// Kraskov neighbours: each invocation keeps the k smallest distances in a private array.
#define TFM_CORR_MAX_K 16u
// Binned mutual information: the joint histogram of one voxel in shared memory (uint counts).
#define TFM_CORR_MAX_BINS 64u
// ... with one workgroup per voxel only beyond this many members: below, one invocation per voxel
// counts its y bins per x bin in a slice of TFM_CORR_BIN_STRIDE words (65: the slices of
// neighbouring invocations start in different banks), about 5 M + 2 bins loop iterations.
#define TFM_CORR_MI_BINNED_INVOCATION_MAX_MEMBERS 4096u
#define TFM_CORR_BIN_STRIDE 65u
// The histogram's words: a voxel's bins x bins counts, or the invocations' slices.
#define TFM_CORR_JOINT_WORDS (TFM_CORR_INVOCATION_WORKGROUP * TFM_CORR_BIN_STRIDE)

#define TFM_CORR_FLAG_REF_CONSTANT 1u  // the reference series is constant
#define TFM_CORR_FLAG_REF_TIES 2u      // the reference series has ties (kendall sorts x tie groups by y)

#if defined(__cplusplus) || defined(TFM_WANT_CORRELATION_PUSH)
TFM_PUSH_CONSTANTS(CorrelationPush) {
  uint voxel_count;   // voxels in this chunk
  uint member_count;  // M
  uint param;         // mi-binned: bins; mi-kraskov: k
  uint flags;         // TFM_CORR_FLAG_*
  float ref_lo;       // mi-binned: min and max of the reference series
  float ref_hi;
  float ref_norm;     // pearson: sum of squared centred x; spearman: sum of squared centred 2*rank
  uint ref_tied_pairs;  // kendall: pairs tied in x
  float mi_offset;    // mi-binned: ln M; mi-kraskov: digamma(k) + digamma(M)
  // Member-major series (TFM_CORR_SPEC_MEMBER_MAJOR): member m of voxel v is texel
  // m * member_stride + v of the view (an uploaded chunk has stride voxel_count, a device-resident
  // ensemble its whole voxel count). Voxel-major (the uploaded layout of one workgroup per voxel):
  // texel v * member_count + m, and the stride is unused.
  uint member_stride;
} TFM_PUSH_INSTANCE(pc);
#endif

#ifdef __cplusplus
}  // namespace tfm::gpu
#endif
#endif  // TFMATCH_CORRELATION_LAYOUT_H
