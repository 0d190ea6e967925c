// Assembles the tridiagonal M = S^T S, S^T b and b^T b of the voxel least-squares problem
// (DESIGN.md) for one chunk of voxels, adding into 32.32 fixed-point accumulators. b is the
// reference colour T_r(F_r), evaluated here and never stored as a volume. NaN voxels are skipped.
//
// Exactness. Every term a voxel adds (15 of them: (1-w)^2, w^2, (1-w)w, (1-w)b_c, w b_c, b_c^2)
// is a float in [0, 1], converted on its own to the 64-bit integer floor(term 2^32), and every
// sum is an integer sum modulo 2^64. Integer addition is associative, so the totals are the same
// bits however the terms are grouped: on every run, device, path, chunking and workgroup count.
//
// Layout of the work. Lanes take consecutive quads of voxels (one vec4 load of each field per
// lane and step: a subgroup reads one contiguous span, coalesced), grid-stride over the chunk.
// The reference TF is read from the buffer or, with TF_CACHE_ENTRIES, from a private copy.
// Where the terms go depends on MODE (chosen by the host, kernels/voxel_pair.cpp):
//  - RUNS_SHARED / RUNS_GLOBAL (GPUs): each lane sums the terms of its current TF bin in
//    registers and adds them to the workgroup's shared accumulators (or straight to the global
//    ones when the 6N+4 slots do not fit shared memory) only when its bin changes: once per run
//    of voxels in one bin, not once per voxel. The workgroup adds its shared totals to the
//    global accumulators once per slot.
//  - PRIVATE (CPU devices such as lavapipe): each lane keeps its own histogram of the 11 bin
//    terms for every TF entry in invocation-private memory and adds to it without atomics or
//    branches: on a CPU, lanes are SIMD lanes of one thread, divergent branches cost as much as
//    taken ones and atomics are locked instructions, so a branch-free private histogram is what
//    keeps the voxel loop as cheap as a scalar CPU loop. Each lane adds its histogram to the
//    global accumulators once at the end, so a lane must cover many voxels (the host sizes it).
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

layout(local_size_x_id = TFM_SPEC_WORKGROUP_X) in;
layout(constant_id = TFM_ASSEMBLE_SPEC_MODE) const uint MODE = TFM_REDUCE_RUNS_SHARED;
// Slots of the workgroup-shared accumulators (1 unless MODE is RUNS_SHARED).
layout(constant_id = TFM_ASSEMBLE_SPEC_SHARED_SLOTS) const uint SHARED_SLOTS = 1u;
// TF entries of each lane's private histogram (0 unless MODE is PRIVATE).
layout(constant_id = TFM_ASSEMBLE_SPEC_PRIVATE_BINS) const uint PRIVATE_BINS = 0u;
// Reference TF entries copied into private memory (0: read the buffer).
layout(constant_id = TFM_ASSEMBLE_SPEC_TF_CACHE) const uint TF_CACHE_ENTRIES = 0u;

// The same buffers seen as floats (the chunk's last voxel_count % 4 voxels) and as quads.
layout(std430, binding = TFM_ASSEMBLE_BINDING_REF_FIELD) readonly buffer RefField { float ref_field[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_REF_FIELD) readonly buffer RefQuads { vec4 ref_quads[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_OPT_FIELD) readonly buffer OptField { float opt_field[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_OPT_FIELD) readonly buffer OptQuads { vec4 opt_quads[]; };
layout(std430, binding = TFM_ASSEMBLE_BINDING_REF_TF) readonly buffer RefTf { vec4 ref_tf[]; };

TFM_DECLARE_ACCUMULATORS(TFM_ASSEMBLE_BINDING_ACCUM)
void add_global(uint k, Fx v) TFM_ADD_GLOBAL(k, v)

void add_slot(uint k, Fx v) {
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_ADD_SHARED(k, v)
  else TFM_ADD_GLOBAL(k, v)
}

// The 11 terms a voxel adds to its bin j, in the order of a private histogram record:
// M[j][j], M[j+1][j+1], M[j][j+1], (S^T b)[j][c], (S^T b)[j+1][c].
#define TERMS 11u

// Adds the 11 term sums of bin j (acc[base + t]) to their accumulator slots.
#define TFM_ADD_BIN(add, j, acc, base)                                              \
  {                                                                                 \
    const uint n_ = pc.opt_tf_size, stb_ = 2u * n_ - 1u;                            \
    add((j), acc[(base) + 0u]);                                                     \
    add((j) + 1u, acc[(base) + 1u]);                                                \
    add(n_ + (j), acc[(base) + 2u]);                                                \
    for (uint c_ = 0u; c_ < 4u; ++c_) {                                             \
      add(stb_ + 4u * (j) + c_, acc[(base) + 3u + c_]);                             \
      add(stb_ + 4u * ((j) + 1u) + c_, acc[(base) + 7u + c_]);                      \
    }                                                                               \
  }

vec4 tf_cache[TF_CACHE_ENTRIES + 1u];
Fx hist[TERMS * PRIVATE_BINS + 1u];
Fx run[TERMS];    // RUNS modes: sums of the current bin
uint run_bin;     // RUNS modes: the current bin, or NO_BIN
const uint NO_BIN = 0xFFFFFFFFu;
Fx btb[4];        // sum of b_c^2, per channel
uint voxels;      // voxels with data in both fields

vec4 ref_entry(uint j) { return TF_CACHE_ENTRIES > 0u ? tf_cache[j] : ref_tf[j]; }

void flush_run() {
  if (run_bin == NO_BIN) return;
  TFM_ADD_BIN(add_slot, run_bin, run, 0u)
  for (uint t = 0u; t < TERMS; ++t) run[t] = FX_ZERO;
}

void take(float ref_value, float opt_value) {
  const uint n = pc.opt_tf_size;
  uint jr, jo;
  float wr, wo;
  const bool ref_ok = tf_coordinate(ref_value, pc.ref_lo, pc.ref_scale, pc.ref_tf_size, jr, wr);
  const bool ok = tf_coordinate(opt_value, pc.opt_lo, pc.opt_scale, n, jo, wo) && ref_ok;
  // Without data the terms are 0 (private mode adds them: no branch), b likewise. `precise`
  // keeps the products and sums unfused, so every device (and the CPU reference of the exact
  // sums, assemble_normal_equations_fixed_point) forms the same float terms.
  precise vec4 b = (1.0 - wr) * ref_entry(jr) + wr * ref_entry(jr + 1u);
  b = ok ? clamp(b, 0.0, 1.0) : vec4(0.0);
  const float w = ok ? wo : 0.0;
  const float u = ok ? 1.0 - wo : 0.0;
  // The terms are listed out (no arrays, no loops): every index below is a constant.
  const Fx t0 = fx_term(u * u), t1 = fx_term(w * w), t2 = fx_term(u * w);
  const Fx t3 = fx_term(u * b.x), t4 = fx_term(u * b.y), t5 = fx_term(u * b.z), t6 = fx_term(u * b.w);
  const Fx t7 = fx_term(w * b.x), t8 = fx_term(w * b.y), t9 = fx_term(w * b.z), t10 = fx_term(w * b.w);
  for (uint c = 0u; c < 4u; ++c) fx_sum(btb[c], fx_term(b[c] * b[c]));
  voxels += ok ? 1u : 0u;
#define TFM_ADD_TERMS(acc, base)                                                     \
  fx_sum(acc[(base) + 0u], t0), fx_sum(acc[(base) + 1u], t1), fx_sum(acc[(base) + 2u], t2), \
  fx_sum(acc[(base) + 3u], t3), fx_sum(acc[(base) + 4u], t4), fx_sum(acc[(base) + 5u], t5), \
  fx_sum(acc[(base) + 6u], t6), fx_sum(acc[(base) + 7u], t7), fx_sum(acc[(base) + 8u], t8), \
  fx_sum(acc[(base) + 9u], t9), fx_sum(acc[(base) + 10u], t10)
  if (MODE == TFM_REDUCE_PRIVATE) {
    const uint base = TERMS * (ok ? jo : 0u);
    TFM_ADD_TERMS(hist, base);
  } else if (ok) {
    if (jo != run_bin) {
      flush_run();
      run_bin = jo;
    }
    TFM_ADD_TERMS(run, 0u);
  }
}

void main() {
  const uint n = pc.opt_tf_size;
  const uint slots = TFM_ASSEMBLE_SLOTS(n);
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_ZERO(slots)
  for (uint j = 0u; j < TF_CACHE_ENTRIES; ++j) tf_cache[j] = ref_tf[j];
  for (uint j = 0u; j < PRIVATE_BINS; ++j)
    for (uint t = 0u; t < TERMS; ++t) hist[TERMS * j + t] = FX_ZERO;
  for (uint t = 0u; t < TERMS; ++t) run[t] = FX_ZERO;
  for (uint c = 0u; c < 4u; ++c) btb[c] = FX_ZERO;
  run_bin = NO_BIN;
  voxels = 0u;

  // Subgroups take segments of TFM_REDUCE_SEGMENT_STEPS quads per lane, lanes on consecutive
  // quads in each step: every step reads one contiguous span, and each subgroup streams through
  // its own part of the chunk.
  const uint quads = pc.voxel_count / 4u;
  const uint segment = gl_SubgroupSize * TFM_REDUCE_SEGMENT_STEPS;
  const uint subgroups = gl_NumWorkGroups.x * gl_NumSubgroups;
  for (uint s = gl_WorkGroupID.x * gl_NumSubgroups + gl_SubgroupID; s * segment < quads; s += subgroups) {
    const uint end = min(s * segment + segment, quads);
    for (uint q = s * segment + gl_SubgroupInvocationID; q < end; q += gl_SubgroupSize) {
      const vec4 r = ref_quads[q];
      const vec4 o = opt_quads[q];
      take(r.x, o.x);
      take(r.y, o.y);
      take(r.z, o.z);
      take(r.w, o.w);
    }
  }
  if (gl_GlobalInvocationID.x == 0u)
    for (uint i = 4u * quads; i < pc.voxel_count; ++i) take(ref_field[i], opt_field[i]);

  if (MODE == TFM_REDUCE_PRIVATE) {
    for (uint j = 0u; j + 1u < n; ++j) TFM_ADD_BIN(add_global, j, hist, TERMS * j)
  } else {
    flush_run();
  }
  for (uint c = 0u; c < 4u; ++c) add_slot(6u * n - 1u + c, btb[c]);
  add_slot(6u * n + 3u, fx_count(voxels));

  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_SHARED_ACCUMULATORS_FLUSH(slots)
}
