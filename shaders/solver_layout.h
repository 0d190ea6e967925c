// Interfaces of the matrix-free solver kernels (sparse S x / S^T r, CGLS vector steps, gradient
// descent): bindings, push-constant blocks, accumulator layouts and the CGLS state record. Included
// by GLSL and by kernels/*.cpp, which static_assert the C++ sizes.
#ifndef TFMATCH_SOLVER_LAYOUT_H
#define TFMATCH_SOLVER_LAYOUT_H

#include "shared_layout.h"

#ifdef __cplusplus
namespace tfm::gpu {
struct vec4 { float x, y, z, w; };
struct uvec4 { uint x, y, z, w; };
#endif

// Workgroup of the single-workgroup kernels over TF-sized vectors (cgls_vectors, gd_update):
// they loop over N and reduce in shared memory in a fixed order (deterministic).
#define TFM_VECTOR_WORKGROUP 256

// Signed sums over a TF (S^T r, gradients): 4N signed 32.32 fixed-point slots (fixed_point.glsl,
// two's complement, TFM_FIXED_SLOT_WORDS words each), the slot of TF entry j, channel c is 4j + c.
#define TFM_TF_GRADIENT_SLOTS(n) (4u * (n))

// Coordinate field: per voxel the TF coordinate x = clamp((v - lo) * scale, 0, N-1) of the
// optimized field (exactly as tf_coordinate computes it), or TFM_NO_DATA when either field has
// no data there. Valid coordinates are >= 0, so a negative sentinel survives any NaN handling.
#define TFM_NO_DATA (-1.0)

// ---- sparse_prepare.comp: coordinates and b (reference colours) per voxel ------------------------
// Specialization: workgroup size only. Both fields as R32F texels, the reference TF as RGBA32F
// texels; the coordinate chunk bound twice (floats, vec4 quads).
#define TFM_PREPARE_BINDING_REF_FIELD 0
#define TFM_PREPARE_BINDING_OPT_FIELD 1
#define TFM_PREPARE_BINDING_REF_TF 2
#define TFM_PREPARE_BINDING_COORD 3
#define TFM_PREPARE_BINDING_RGBA 4
#define TFM_PREPARE_BINDING_COORD_QUADS 5
// The TFM_WEIGHTED variants of prepare, gather and scatter (weighted CGLS, --weights): each
// voxel's row and b scaled by sqrt(weight). Prepare reads the weights field (a texel view, from
// weight_field_shift) and writes each voxel's scale; gather and scatter read the scales.
#define TFM_PREPARE_BINDING_WEIGHTS 6
#define TFM_PREPARE_BINDING_SCALE 7

#if defined(__cplusplus) || defined(TFM_WANT_PREPARE_PUSH)
TFM_PUSH_CONSTANTS(PreparePush) {
  uint voxel_count;   // voxels in this range of a chunk of the voxel vectors
  uint field_shift;   // texel of the range's first voxel in the bound reference-field view
  uint first_voxel;   // the range's first voxel in its chunk (a multiple of 4)
  uint opt_tf_size;
  uint ref_tf_size;
  float ref_lo;
  float ref_scale;
  float opt_lo;
  float opt_scale;
  uint opt_field_shift;  // the same in the second field's view (the fields may store voxels in
                         // different formats, so their views start at different texels)
  uint weight_field_shift;  // the same in the weights' view (TFM_WEIGHTED)
} TFM_PUSH_INSTANCE(pc);
#endif

// ---- sparse_gather.comp: q = S x per voxel, optionally ||q||^2 per channel -----------------------
// Specialization: workgroup size (TFM_SPEC_WORKGROUP_X), then these. NORM_SCALED: the norm is of
// q / p_scale (CGLS state), a power of two >= max |x|, so the squares keep their relative
// precision in fixed point however small x gets.
#define TFM_GATHER_SPEC_WRITE_OUT 1        // store q
#define TFM_GATHER_SPEC_ACCUMULATE_NORM 2  // add ||q_c||^2 to TFM_GATHER_NORM_SLOTS unsigned slots
#define TFM_GATHER_SPEC_NORM_SCALED 3
#define TFM_GATHER_BINDING_COORD 0
#define TFM_GATHER_BINDING_X 1
#define TFM_GATHER_BINDING_OUT 2
#define TFM_GATHER_BINDING_NORM 3
#define TFM_GATHER_BINDING_STATE 4
#define TFM_GATHER_BINDING_COORD_QUADS 5  // the range's coordinates as RGBA32F texels
#define TFM_GATHER_NORM_SLOTS 4u
#define TFM_GATHER_BINDING_SCALE 6        // TFM_WEIGHTED: each voxel's row scale, float

// ---- sparse_scatter.comp: s += S^T r (signed slots), optionally after r -= alpha (S p) ----------
// Accumulators: TFM_TF_GRADIENT_SLOTS(N) signed slots. Specialization: workgroup size
// (TFM_SPEC_WORKGROUP_X), then these.
#define TFM_SCATTER_SPEC_MODE 1             // TFM_REDUCE_* (shared_layout.h)
#define TFM_SCATTER_SPEC_SHARED_SLOTS 2     // slots of workgroup-shared accumulators (RUNS_SHARED)
#define TFM_SCATTER_SPEC_PRIVATE_BINS 3     // TF entries of each lane's private histogram (PRIVATE)
#define TFM_SCATTER_SPEC_UPDATE_RESIDUAL 4  // r -= alpha (S p) first, alpha from the CGLS state
#define TFM_SCATTER_BINDING_COORD 0
#define TFM_SCATTER_BINDING_RESIDUAL 1
#define TFM_SCATTER_BINDING_P 2
#define TFM_SCATTER_BINDING_STATE 3
#define TFM_SCATTER_BINDING_ACCUM 4
#define TFM_SCATTER_BINDING_COORD_QUADS 5       // the range's coordinates as RGBA32F texels
#define TFM_SCATTER_BINDING_RESIDUAL_TEXELS 6   // the range's r, one RGBA32F texel per voxel
#define TFM_SCATTER_BINDING_SCALE 7             // TFM_WEIGHTED: each voxel's row scale, float

// Push constants of sparse_gather and sparse_scatter: one range of a chunk of the voxel vectors.
// p (scatter) and x (gather) are bound as N RGBA32F texels.
#if defined(__cplusplus) || defined(TFM_WANT_SPARSE_PUSH)
TFM_PUSH_CONSTANTS(SparsePush) {
  uint voxel_count;  // voxels in this range
  uint tf_size;      // N
  uint first_voxel;  // the range's first voxel in its chunk (a multiple of 4)
} TFM_PUSH_INSTANCE(pc);
#endif

// ---- cgls_vectors.comp: the TF-sized steps of preconditioned CGLS, four channels at once ---------
// The preconditioner P = L D L^T (L unit lower bidiagonal): Jacobi, diag(M + R), without
// smoothing; diag(M) + R with it, so the smoothing is inverted exactly (cgls_preconditioner()).
// Specialization: workgroup size (a power of two) only.
#define TFM_CGLS_BINDING_S_ACCUM 0     // signed slots of S^T r (from sparse_scatter)
#define TFM_CGLS_BINDING_DELTA_ACCUM 1 // ||S p||^2 (from sparse_gather)
#define TFM_CGLS_BINDING_INV_PIVOT 2   // 1 / D_j per entry, 0 for an entry that stays 0
#define TFM_CGLS_BINDING_X 3
#define TFM_CGLS_BINDING_P 4
#define TFM_CGLS_BINDING_STATE 5
#define TFM_CGLS_BINDING_LOWER 6       // L_{j+1,j} per entry (N floats, the last unused)
#define TFM_CGLS_BINDING_Z 7           // N RGBA: z = P^-1 s, written only when P is not diagonal

#define TFM_CGLS_STAGE_INIT 0u       // s = S^T b, z = P^-1 s, p = z, gamma = s.z, x = 0
#define TFM_CGLS_STAGE_STEP 1u       // delta = ||S p||^2 + p.R p, alpha = gamma / delta, x += alpha p
#define TFM_CGLS_STAGE_DIRECTION 2u  // s = S^T r - R x, z = P^-1 s, beta, p = z + beta p, stop test
// Stop test: ||s||^2 <= tolerance2 ||s0||^2, or s.z = s^T P^-1 s <= u^2 (ridge + 4 smooth) ||x||^2,
// u = 2^-24: the float32 floor, where the residual in P^-1's norm is down to what R makes of the
// rounding of x.

// Per-channel scalars of the four CGLS runs (std430: vec4/uvec4 members, no padding).
struct CglsState {
  vec4 gamma;        // s.z of the current direction
  vec4 alpha;        // step of the current iteration (0 for stopped channels)
  vec4 s_norm2;      // ||s||^2 of the latest iterate
  vec4 s0_norm2;     // ||S^T b||^2
  vec4 p_scale;      // power of two >= max_j |p_j| (1 when p = 0): sparse_gather's norm scale
  uvec4 iterations;  // completed iterations per channel
  uvec4 running;     // 1 while a channel iterates; 0 once converged or broken down
};

#if defined(__cplusplus) || defined(TFM_WANT_CGLS_PUSH)
TFM_PUSH_CONSTANTS(CglsPush) {
  uint tf_size;
  uint stage;         // TFM_CGLS_STAGE_*
  float ridge_weight;      // absolute weights of R = ridge I + smooth D^T D
  float smooth_weight;
  float tolerance2;   // stop when ||s||^2 <= tolerance2 * ||s0||^2 (or at the float32 floor)
  uint bidiagonal;    // 1: L has multipliers (substitution, serial); 0: P = D (entry by entry)
  uint pad1, pad2;
} TFM_PUSH_INSTANCE(pc);
#endif

// ---- gd_gradient.comp: loss and signed gradient accumulators over one chunk ----------------------
// Uses VoxelPairPush (shared_layout.h). Specialization: workgroup size (TFM_SPEC_WORKGROUP_X),
// then these. Slots: the gradient, TFM_TF_GRADIENT_SLOTS(N) signed slots, then the loss per
// channel as 4 unsigned slots from TFM_GD_LOSS_SLOT(N) (word 2 TFM_GD_LOSS_SLOT(N)).
#define TFM_GD_SPEC_MODE 1          // TFM_REDUCE_* (shared_layout.h)
#define TFM_GD_SPEC_SHARED_SLOTS 2  // slots of workgroup-shared gradient accumulators (RUNS_SHARED)
#define TFM_GD_SPEC_PRIVATE_BINS 3  // TF entries of each lane's private histogram (PRIVATE)
#define TFM_GD_SPEC_LOSS_L1 4       // 1: l1 loss, 0: l2
#define TFM_GD_SPEC_TF_CACHE 5      // reference TF entries copied per lane (0: read the buffer)
#define TFM_GD_BINDING_REF_FIELD 0
#define TFM_GD_BINDING_OPT_FIELD 1
#define TFM_GD_BINDING_REF_TF 2
#define TFM_GD_BINDING_X 3
#define TFM_GD_BINDING_ACCUM 4
#define TFM_GD_BINDING_REF_QUADS 5  // the chunks again as RGBA32F texel buffers (quads of voxels)
#define TFM_GD_BINDING_OPT_QUADS 6
#define TFM_GD_LOSS_SLOT(n) TFM_TF_GRADIENT_SLOTS(n)
// Loop iterations tf_residual_walk.glsl runs per quad of a lane (the walk's 1, and its loop over
// the quad's 4 voxels, 4 + 1 as it exits): what lavapipe's loop counter sees (kernels/reduction.h).
#define TFM_RESIDUAL_WALK_LOOPS_PER_QUAD 6u
#define TFM_GD_ACCUM_WORDS(n) (TFM_FIXED_SLOT_WORDS * (TFM_GD_LOSS_SLOT(n) + 4u))

// ---- gd_update.comp: one SGD or Adam step on the TF, projected to [0,1] ---------------------------
// Specialization: workgroup size only.
#define TFM_GD_UPDATE_BINDING_ACCUM 0
#define TFM_GD_UPDATE_BINDING_X 1
#define TFM_GD_UPDATE_BINDING_M 2
#define TFM_GD_UPDATE_BINDING_V 3
#define TFM_GD_UPDATE_BINDING_INV_DIAG 4
#define TFM_GD_UPDATE_BINDING_GRADIENT 5  // out: the gradient of this step (N RGBA)

#define TFM_GD_OPTIMIZER_SGD 0u
#define TFM_GD_OPTIMIZER_ADAM 1u

#if defined(__cplusplus) || defined(TFM_WANT_GD_UPDATE_PUSH)
// Loss L(x) = data_scale * sum_i phi(S x - b)_i + reg_scale/2 * x^T R x, so the gradient is
// g = data_scale * (accumulated sum) + reg_scale * R x. SGD steps are Jacobi-scaled:
// x -= lr * g / (reg_scale * diag(M + R)), i.e. lr = 1 is a diagonal Newton step of the l2 loss.
TFM_PUSH_CONSTANTS(GdUpdatePush) {
  uint tf_size;
  uint optimizer;      // TFM_GD_OPTIMIZER_*
  float data_scale;
  float reg_scale;
  float ridge_weight;       // absolute weights of R = ridge I + smooth D^T D
  float smooth_weight;
  float lr;            // step size of this iteration
  float beta1;         // Adam moment decay rates
  float beta2;
  float bias1;         // 1 / (1 - beta1^t)
  float bias2;         // 1 / (1 - beta2^t)
  float epsilon;
} TFM_PUSH_INSTANCE(pc);
#endif

// ---- irls_assemble.comp: one pass of iteratively reweighted least squares (solver `irls`) -------
// Uses VoxelPairPush (shared_layout.h). Per voxel and channel c the residual e = T_o(F_o) - b at
// the current TF x, as gd_gradient forms it, gives the weight w_c = delta_c / max(|e_c|, delta_c)
// in (0, 1]; the pass sums the weighted tridiagonal normal equations of every channel and the l1
// loss at x. Slots (signed 32.32, fixed_point.glsl; the sums themselves are >= 0): three sets of
// TFM_TF_GRADIENT_SLOTS(N), slot 4j + c of set s at TFM_IRLS_SET_SLOT(s, j, c, N):
//   set 0 (TFM_IRLS_SET_DIAG): sum w_c (1-t)^2 into entry j and w_c t^2 into j + 1 (diagonal),
//   set 1 (TFM_IRLS_SET_OFF):  sum w_c (1-t) t into entry j (the off-diagonal (j, j+1)),
//   set 2 (TFM_IRLS_SET_RHS):  sum w_c (1-t) b_c into entry j and w_c t b_c into j + 1,
// t the voxel's weight between entries j and j + 1; then the l1 loss per channel (sum |e_c|) as
// 4 unsigned slots from TFM_IRLS_LOSS_SLOT(N). Specialization and bindings with the numbers of
// gd_gradient's (constant 4, its loss choice, unused): kernels/tf_residual_pass.h drives both.
#define TFM_IRLS_SPEC_MODE 1          // TFM_REDUCE_* (shared_layout.h)
#define TFM_IRLS_SPEC_SHARED_SLOTS 2  // slots of workgroup-shared accumulators (RUNS_SHARED)
#define TFM_IRLS_SPEC_PRIVATE_BINS 3  // TF entries of each lane's private histograms (PRIVATE)
#define TFM_IRLS_SPEC_TF_CACHE 5      // reference TF entries copied per lane (0: read the buffer)
#define TFM_IRLS_BINDING_REF_FIELD 0
#define TFM_IRLS_BINDING_OPT_FIELD 1
#define TFM_IRLS_BINDING_REF_TF 2
#define TFM_IRLS_BINDING_STATE 3      // x (N RGBA entries), then delta per channel (one vec4)
#define TFM_IRLS_BINDING_ACCUM 4
#define TFM_IRLS_BINDING_REF_QUADS 5  // the chunks again as RGBA32F texel buffers (quads of voxels)
#define TFM_IRLS_BINDING_OPT_QUADS 6
#define TFM_IRLS_SETS 3u
#define TFM_IRLS_SET_DIAG 0u
#define TFM_IRLS_SET_OFF 1u
#define TFM_IRLS_SET_RHS 2u
#define TFM_IRLS_SET_SLOT(s, j, c, n) ((s) * TFM_TF_GRADIENT_SLOTS(n) + 4u * (j) + (c))
#define TFM_IRLS_LOSS_SLOT(n) (TFM_IRLS_SETS * TFM_TF_GRADIENT_SLOTS(n))
#define TFM_IRLS_ACCUM_WORDS(n) (TFM_FIXED_SLOT_WORDS * (TFM_IRLS_LOSS_SLOT(n) + 4u))

#ifdef __cplusplus
}  // namespace tfm::gpu
#endif
#endif  // TFMATCH_SOLVER_LAYOUT_H
