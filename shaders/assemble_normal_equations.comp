// Assembles the tridiagonal M = S^T S, S^T b and b^T b of the voxel least-squares problem
// (DESIGN.md) for one chunk of voxels, adding into 32.32 fixed-point accumulators. b is the
// reference colour T_r(F_r), evaluated here and never stored as a volume. Voxels without data (NaN, ±Inf) are skipped.
//
// Weights (the TFM_WEIGHTED variant): voxel i's terms are s_i times the terms above, s_i a float
// in [0, 1] read from a third field (visibility weights: kernels/visibility_weights.h, multiples
// of 2^-16), each product rounded once to float (`precise`), so the terms are still floats in
// [0, 1] and the sums exact; the voxel count stays a count.
//
// Exactness. Every term a voxel adds (15 of them: (1-w)^2, w^2, (1-w)w, (1-w)b_c, w b_c, b_c^2,
// and with WITH_BEFORE the 4 squares of the loss before optimization, (T_r(F_o) - b)_c^2)
// is a float in [0, 1], converted on its own to the 64-bit integer floor(term 2^32), and every
// sum is an integer sum modulo 2^64. Integer addition is associative, so the totals are the same
// bits however the terms are grouped: on every run, device, path, chunking and workgroup count.
//
// Layout of the work. Lanes take consecutive quads of voxels (one RGBA32F texel of each field per
// lane and step: a subgroup reads one contiguous span), grid-stride over the dispatch's range of
// the chunk. Fields and the reference TF are read as uniform texel buffers, not storage buffers:
// GPUs fetch them through the texture path as fast as plain loads, and CPU devices (lavapipe)
// turn a texel fetch into one vector gather, where a storage-buffer load with a per-lane index
// is a loop over the SIMD lanes that inserts each value through memory (measured on lavapipe:
// the loads alone 300 ms for 41.5 M voxels as storage buffers, 20 ms as texels).
// Where the terms go depends on MODE (chosen by the host, kernels/reduction.cpp):
//  - RUNS_SHARED / RUNS_GLOBAL (GPUs): each lane sums the terms of its current TF bin in
//    registers and adds them to the workgroup's shared accumulators (or straight to the global
//    ones when the 6N+4 slots do not fit shared memory) only when its bin changes: once per run
//    of voxels in one bin, not once per voxel. The workgroup adds its shared totals to the
//    global accumulators once per slot.
//  - PRIVATE (CPU devices such as lavapipe): each lane keeps its own histogram of the bin terms
//    for every TF entry in invocation-private memory and adds to it without atomics or branches:
//    on a CPU, lanes are SIMD lanes of one thread, a divergent branch costs as much as a taken
//    one (lavapipe runs both sides under a mask; measured: register runs flushed on a bin change
//    are 1.2-1.5x slower than adding every voxel to the histogram) and atomics are locked
//    instructions. Each lane adds its histogram to the global accumulators once at the end, so
//    a lane must cover many voxels (the host sizes it), and a workgroup is one subgroup (a CPU
//    device runs a workgroup on one thread: small groups spread the lanes over every core). A histogram of all 11 terms of N entries
//    costs 88 N bytes per lane; above 1024 entries the host splits the 11 terms into passes that
//    each hold TERM_COUNT terms of every entry, so the private memory stays bounded and TF sizes
//    up to 4096 cost a few cheap passes instead of a path change. The passes are the rows of one
//    dispatch of one pipeline (row y adds terms TERM_FIRST + y TERM_COUNT onwards, chosen at run
//    time), so a CPU device compiles TERM_COUNT arrays of N once, not 11 over a pipeline per pass.
// Term conversions use 32-bit float-to-integer conversions (fx_term): a 64-bit one has no vector
// instruction on x86 before AVX-512 and was a third of the kernel's time on lavapipe.
// Atomics: TFM_INT64 builds (devices with 64-bit buffer and shared atomics) add one 64-bit word
// per slot; the default build adds the two 32-bit words of fixed_point.glsl with their carry.
#version 450
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#ifdef TFM_INT64
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#endif
#define TFM_WANT_VOXEL_PAIR_PUSH
#include "shared_layout.h"
#include "tf_common.glsl"
#include "fixed_point_accumulators.glsl"
#include "quad_segments.glsl"

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_ASSEMBLE_SPEC_MODE) const uint MODE = TFM_REDUCE_RUNS_SHARED;
// Slots of the workgroup-shared accumulators (1 unless MODE is RUNS_SHARED).
layout(constant_id = TFM_ASSEMBLE_SPEC_SHARED_SLOTS) const uint SHARED_SLOTS = 1u;
// TF entries of each lane's private histogram (0 unless MODE is PRIVATE).
layout(constant_id = TFM_ASSEMBLE_SPEC_PRIVATE_BINS) const uint PRIVATE_BINS = 0u;
// The bin terms a workgroup row adds: TERM_COUNT of the 11, from TERM_FIRST + TERM_COUNT
// gl_WorkGroupID.y (one row of all 11 but in PRIVATE passes, where each row is a pass). The row
// whose first term is 0 also sums b^T b, the voxel count and the before loss.
layout(constant_id = TFM_ASSEMBLE_SPEC_TERM_FIRST) const uint TERM_FIRST = 0u;
layout(constant_id = TFM_ASSEMBLE_SPEC_TERM_COUNT) const uint TERM_COUNT = 11u;
// Also sum the loss before optimization (a reference TF of another size than N). A constant, not
// a push value: a branch on a push value in the voxel loop made the plain assembly ~40% slower on
// lavapipe (measured), so pipelines without it compile the loop without it.
layout(constant_id = TFM_ASSEMBLE_SPEC_WITH_BEFORE) const bool WITH_BEFORE = false;

#define TFM_FIELDS_REF TFM_ASSEMBLE_BINDING_REF_FIELD
#define TFM_FIELDS_OPT TFM_ASSEMBLE_BINDING_OPT_FIELD
#define TFM_FIELDS_REF_QUADS TFM_ASSEMBLE_BINDING_REF_QUADS
#define TFM_FIELDS_OPT_QUADS TFM_ASSEMBLE_BINDING_OPT_QUADS
#define TFM_FIELDS_SPEC_NX TFM_ASSEMBLE_SPEC_IMAGE_NX
#define TFM_FIELDS_SPEC_NY TFM_ASSEMBLE_SPEC_IMAGE_NY
#include "voxel_pair_fields.glsl"
layout(binding = TFM_ASSEMBLE_BINDING_REF_TF) uniform samplerBuffer ref_tf;
#ifdef TFM_WEIGHTED
layout(binding = TFM_ASSEMBLE_BINDING_WEIGHTS) uniform samplerBuffer weight_field;
layout(binding = TFM_ASSEMBLE_BINDING_WEIGHT_QUADS) uniform samplerBuffer weight_quads;
#define WEIGHT_VOXEL(i) texelFetch(weight_field, int(i)).x
#define WEIGHT_QUAD(q) texelFetch(weight_quads, int(q))
// s t, rounded once.
float weighted(float s, float t) {
  precise float st = s * t;
  return st;
}
#else
#define WEIGHT_VOXEL(i) 1.0
#define WEIGHT_QUAD(q) vec4(1.0)
#define weighted(s, t) (t)
#endif

TFM_DECLARE_ACCUMULATORS(TFM_ASSEMBLE_BINDING_ACCUM)
void add_global(uint k, Fx v) TFM_ADD_GLOBAL(k, v)

void add_slot(uint k, Fx v) {
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_ADD_SHARED(k, v)
  else TFM_ADD_GLOBAL(k, v)
}

// The 11 terms a voxel adds to its bin j, in this order: M[j][j], M[j+1][j+1], M[j][j+1],
// (S^T b)[j][c], (S^T b)[j+1][c].
#define TERMS 11u
// Accumulator slot of term t of bin j (slot layout: shared_layout.h, TFM_ASSEMBLE_SLOTS).
uint term_slot(uint t, uint j) {
  const uint n = pc.opt_tf_size, stb = 2u * n - 1u;
  return t == 0u ? j : t == 1u ? j + 1u : t == 2u ? n + j : t < 7u ? stb + 4u * j + (t - 3u) : stb + 4u * (j + 1u) + (t - 7u);
}
// One row holds every term: the row's terms are constants the compiler folds.
const bool ALL_TERMS = TERM_COUNT >= TERMS;
// The first term of this workgroup row.
uint row_first() { return ALL_TERMS ? TERM_FIRST : TERM_FIRST + gl_WorkGroupID.y * TERM_COUNT; }
// Term t of a voxel with TF weights u = 1 - w, w and reference colour b, as fixed point (0 for
// t >= 11): one expression where t is a constant, a choice among the 11 where it is not.
Fx voxel_term(uint t, float s, float u, float w, vec4 b) {
  // Each term is a product of u or w with u, w or a channel of b.
  const float left = t == 1u || t >= 7u ? w : u;
  const float right = t == 0u ? u : t < 3u ? w : b[(t - 3u) & 3u];
  return t < TERMS ? fx_term(weighted(s, left * right)) : FX_ZERO;
}

// PRIVATE: one histogram per term of the row, entry j at [j]: hist<a> sums the row's term
// row_first() + a (a >= TERM_COUNT gets a one-element array it never touches). One array per
// term, not one of TERM_COUNT N sums: lavapipe
// compiles a private array in a time that grows faster than linearly with its size (the time is
// in LLVM's instruction scheduler; most likely the driver zero-fills the array in one block of
// stores), so eleven arrays of N compile several times faster than one of 11 N and run as fast
// (docs/benchmarks.md, "A cold shader cache"; test ShaderPrivateArrays).
#define TFM_EACH_TERM(M) M(0) M(1) M(2) M(3) M(4) M(5) M(6) M(7) M(8) M(9) M(10)
#define TFM_DECLARE_HIST(a) Fx hist##a[uint(a) < TERM_COUNT ? PRIVATE_BINS + 1u : 1u];
TFM_EACH_TERM(TFM_DECLARE_HIST)
Fx run[TERMS];    // RUNS modes: sums of the current bin
uint run_bin;     // RUNS modes: the current bin, or NO_BIN
const uint NO_BIN = 0xFFFFFFFFu;
Fx btb[4];        // sum of b_c^2, per channel
Fx before[4];     // sum of (T_r(F_o) - b)_c^2, per channel (WITH_BEFORE)
uint voxels;      // voxels with data in both fields

void flush_run() {
  if (run_bin == NO_BIN) return;
  for (uint t = 0u; t < TERMS; ++t) {
    add_slot(term_slot(t, run_bin), run[t]);
    run[t] = FX_ZERO;
  }
}

void take(float ref_value, float opt_value, float s) {
  const uint n = pc.opt_tf_size;
  uint jr, jo;
  float wr, wo;
  const bool ref_ok = tf_coordinate(ref_value, pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr);
  const bool ok = tf_coordinate(opt_value, pc.opt_lo, pc.opt_scale, n, jo, wo) && ref_ok;
  // Without data the terms are 0 (private mode adds them: no branch), b likewise. `precise`
  // keeps the products and sums unfused, so every device (and the CPU reference of the exact
  // sums, assemble_normal_equations_fixed_point) forms the same float terms.
  precise vec4 b = (1.0 - wr) * texelFetch(ref_tf, int(jr)) + wr * texelFetch(ref_tf, int(jr + 1u));
  b = ok ? clamp(b, 0.0, 1.0) : vec4(0.0);
  const float w = ok ? wo : 0.0;
  const float u = ok ? 1.0 - wo : 0.0;
  if (row_first() == 0u) {
    for (uint c = 0u; c < 4u; ++c) fx_sum(btb[c], fx_term(weighted(s, b[c] * b[c])));
    voxels += ok ? 1u : 0u;
    // The loss before optimization: the second field shown with the reference TF (its own
    // mapping onto the reference TF's entries), against b. Four sums in registers, no bins.
    if (WITH_BEFORE) {
      uint jb;
      float wb;
      tf_coordinate(opt_value, pc.before_lo, pc.before_scale, pc.ref_tf_size, jb, wb);
      precise vec4 d = (1.0 - wb) * texelFetch(ref_tf, int(jb)) + wb * texelFetch(ref_tf, int(jb + 1u));
      d = ok ? d - b : vec4(0.0);
      for (uint c = 0u; c < 4u; ++c) fx_sum(before[c], fx_term(weighted(s, d[c] * d[c])));
    }
  }
  // The terms are listed out (no arrays, no loops): with one row of all terms every index below
  // is a constant.
  if (MODE == TFM_REDUCE_PRIVATE) {
    const uint j = ok ? jo : 0u, first = row_first();
#define TFM_ADD_HIST(a) if (uint(a) < TERM_COUNT) fx_sum(hist##a[j], voxel_term(first + uint(a), s, u, w, b));
    TFM_EACH_TERM(TFM_ADD_HIST)
  } else if (ok) {
    if (jo != run_bin) {
      flush_run();
      run_bin = jo;
    }
#define TFM_ADD_RUN(i) fx_sum(run[i], voxel_term(uint(i), s, u, w, b));
    TFM_EACH_TERM(TFM_ADD_RUN)
  }
}

void main() {
  const uint n = pc.opt_tf_size;
  const uint slots = TFM_ASSEMBLE_SLOTS(n);
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_ZERO(slots)
  for (uint j = 0u; j < PRIVATE_BINS; ++j) {
#define TFM_ZERO_HIST(a) if (uint(a) < TERM_COUNT) hist##a[j] = FX_ZERO;
    TFM_EACH_TERM(TFM_ZERO_HIST)
  }
  for (uint t = 0u; t < TERMS; ++t) run[t] = FX_ZERO;
  for (uint c = 0u; c < 4u; ++c) btb[c] = before[c] = FX_ZERO;
  run_bin = NO_BIN;
  voxels = 0u;

  // Lanes on consecutive quads, each subgroup through its own segments (quad_segments.glsl).
  const uint quads = pc.voxel_count / 4u;
  TFM_FOR_EACH_QUAD(q, quads) {
    const vec4 r = REF_QUAD(q);
    const vec4 o = OPT_QUAD(q);
    const vec4 s = WEIGHT_QUAD(q);
    take(r.x, o.x, s.x);
    take(r.y, o.y, s.y);
    take(r.z, o.z, s.z);
    take(r.w, o.w, s.w);
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint i = pc.first_voxel + 4u * quads; i < pc.first_voxel + pc.voxel_count; ++i)
      take(REF_VOXEL(i), OPT_VOXEL(i), WEIGHT_VOXEL(i));

  const uint first = row_first();
  if (MODE == TFM_REDUCE_PRIVATE) {
    for (uint j = 0u; j + 1u < n; ++j) {
#define TFM_FLUSH_HIST(a) \
      if (uint(a) < TERM_COUNT && first + uint(a) < TERMS) add_global(term_slot(first + uint(a), j), hist##a[j]);
      TFM_EACH_TERM(TFM_FLUSH_HIST)
    }
  } else {
    flush_run();
  }
  if (first == 0u) {
    for (uint c = 0u; c < 4u; ++c) add_slot(6u * n - 1u + c, btb[c]);
    add_slot(6u * n + 3u, fx_count(voxels));
    if (WITH_BEFORE)
      for (uint c = 0u; c < 4u; ++c) add_slot(6u * n + 4u + c, before[c]);
  }

  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_FLUSH(slots)
}
