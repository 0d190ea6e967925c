// Deterministic sums for every accumulating kernel: 32.32 fixed point in two 32-bit words.
//
// One encoding: a slot is a 64-bit integer v / 2^32, low word first (words 2k, 2k+1 of slot k).
// Non-negative totals (sums of squares, counts, M and S^T b) read it as unsigned, < 2^32;
// signed totals (gradients, S^T r) as two's complement, |total| < 2^31. Both are added with the
// same 64-bit integer addition modulo 2^64, which is exact and associative, so totals have the
// same bits whatever the scheduling and however the terms were split between registers, shared
// and global memory (intermediate wrap-around cancels). Only core 32-bit atomics are needed.
// The host decodes with decode_fixed_point (unsigned) and FixedPointTotals (signed).
#ifndef TFMATCH_FIXED_POINT_GLSL
#define TFMATCH_FIXED_POINT_GLSL

#include "shared_layout.h"  // TFM_FIXED_ONE

// Converts a non-negative value below 2^32 to 32.32 fixed point. Exact for every float >= 2^-9;
// smaller values lose less than 2^-32 (truncation).
uvec2 fx_from_float(float c) {
  float whole = floor(c);
  return uvec2(uint((c - whole) * TFM_FIXED_ONE), uint(whole));
}

// -v modulo 2^64.
uvec2 fx_negate(uvec2 v) {
  v = ~v;
  v.x += 1u;
  if (v.x == 0u) v.y += 1u;
  return v;
}

// v (|v| < 2^31) in two's complement. Truncates the magnitude like fx_from_float (towards zero),
// so the error is below 2^-32 and a term and its negation cancel exactly.
uvec2 fx_from_signed(float v) {
  const uvec2 m = fx_from_float(abs(v));
  return v < 0.0 ? fx_negate(m) : m;
}

// acc += v on a thread-private 64-bit fixed-point number.
void fx_add(inout uvec2 acc, uvec2 v) {
  uint lo = acc.x + v.x;
  acc.y += v.y + (lo < acc.x ? 1u : 0u);
  acc.x = lo;
}

// Atomic 64-bit add into words arr[2k] (low) and arr[2k+1] (high) using 32-bit atomics: the
// carry out of the low word is detected from the value the atomic returns, so each carry is
// added exactly once and the final 64-bit total is exact whatever the interleaving. Adding 0
// touches nothing.
#define FX_ATOMIC_ADD(arr, k, v)                                               \
  {                                                                            \
    uvec2 fx_v_ = (v);                                                         \
    if ((fx_v_.x | fx_v_.y) != 0u) {                                           \
      uint fx_old_ = atomicAdd(arr[2u * (k)], fx_v_.x);                        \
      uint fx_hi_ = fx_v_.y + ((fx_old_ + fx_v_.x) < fx_old_ ? 1u : 0u);       \
      if (fx_hi_ != 0u) atomicAdd(arr[2u * (k) + 1u], fx_hi_);                 \
    }                                                                          \
  }

// FX_ATOMIC_ADD into the workgroup's shared slots when `use_shared` (a specialization constant),
// else straight into the global ones.
#define FX_ATOMIC_ADD_TO(use_shared, shared_arr, global_arr, k, v) \
  if (use_shared) {                                                \
    FX_ATOMIC_ADD(shared_arr, (k), (v))                            \
  } else {                                                         \
    FX_ATOMIC_ADD(global_arr, (k), (v))                            \
  }

// Adds float sums `lo` and `hi` (vec4, |.| < 2^31) of TF entries j and j + 1 to the signed slots
// 4j + c and 4(j + 1) + c (channel c), the gradient layout of every kernel that scatters to a TF.
// The four channels are written out, not looped: llvmpipe counts a constant loop with a body this
// large against its limit of loop iterations an invocation (diffdvr_backward.comp flushes at
// samples of its march).
#define FX_ADD_TF_PAIR(use_shared, shared_arr, global_arr, j, lo, hi)           \
  FX_ADD_TF_PAIR_CHANNEL(use_shared, shared_arr, global_arr, j, lo, hi, 0u)   \
  FX_ADD_TF_PAIR_CHANNEL(use_shared, shared_arr, global_arr, j, lo, hi, 1u)   \
  FX_ADD_TF_PAIR_CHANNEL(use_shared, shared_arr, global_arr, j, lo, hi, 2u)   \
  FX_ADD_TF_PAIR_CHANNEL(use_shared, shared_arr, global_arr, j, lo, hi, 3u)
#define FX_ADD_TF_PAIR_CHANNEL(use_shared, shared_arr, global_arr, j, lo, hi, c)                \
  FX_ATOMIC_ADD_TO(use_shared, shared_arr, global_arr, 4u * (j) + (c), fx_from_signed((lo)[c])) \
  FX_ATOMIC_ADD_TO(use_shared, shared_arr, global_arr, 4u * ((j) + 1u) + (c), fx_from_signed((hi)[c]))

// Value of a non-negative 32.32 number (lo, hi) as float.
float fx_to_float(uvec2 v) { return float(v.y) + float(v.x) * (1.0 / TFM_FIXED_ONE); }

// Value of a two's complement 32.32 number as float: the magnitude is formed exactly in integers,
// so cancelling totals (a residual orthogonal to S) lose nothing before the one rounding.
float fx_signed_to_float(uvec2 v) {
  const bool negative = (v.y & 0x80000000u) != 0u;
  const float magnitude = fx_to_float(negative ? fx_negate(v) : v);
  return negative ? -magnitude : magnitude;
}

// The workgroup-shared accumulator pattern: a kernel declares `shared uint s[2 * slots]`,
// zeroes it with FX_SHARED_ZERO, adds with FX_ATOMIC_ADD(s, ...) and ends with FX_SHARED_FLUSH,
// which adds slot k of the workgroup's totals to slot k of the global array once. Every
// invocation of the workgroup must reach both (they contain barriers): no early return before.
#define FX_GROUP_INVOCATIONS (gl_WorkGroupSize.x * gl_WorkGroupSize.y * gl_WorkGroupSize.z)

#define FX_SHARED_ZERO(shared_arr, slots)                                                    \
  {                                                                                          \
    for (uint fx_k_ = gl_LocalInvocationIndex; fx_k_ < 2u * (slots); fx_k_ += FX_GROUP_INVOCATIONS) \
      shared_arr[fx_k_] = 0u;                                                                \
    /* The zeroed slots are visible to the workgroup before any invocation adds to them. */  \
    memoryBarrierShared();                                                                   \
    barrier();                                                                               \
  }

#define FX_SHARED_FLUSH(shared_arr, slots, global_arr)                                          \
  {                                                                                             \
    /* Every shared add of this workgroup is complete before its totals are read. */            \
    memoryBarrierShared();                                                                      \
    barrier();                                                                                  \
    for (uint fx_k_ = gl_LocalInvocationIndex; fx_k_ < (slots); fx_k_ += FX_GROUP_INVOCATIONS) \
      FX_ATOMIC_ADD(global_arr, fx_k_, uvec2(shared_arr[2u * fx_k_], shared_arr[2u * fx_k_ + 1u])) \
  }

#endif
