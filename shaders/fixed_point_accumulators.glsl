// The accumulators of the voxel-reducing kernels (assemble_normal_equations, sparse_scatter,
// gd_gradient) in either of two builds: 32.32 fixed-point sums (fixed_point.glsl) as two 32-bit
// words added with carry, or, with TFM_INT64 (devices with 64-bit buffer and shared atomics),
// one 64-bit word. Both hold the same integer modulo 2^64, so both builds give the same bits.
//
// The including shader enables GL_EXT_shader_explicit_arithmetic_types_int64 and
// GL_EXT_shader_atomic_int64 under TFM_INT64, declares `SHARED_SLOTS` (a specialization
// constant) and then TFM_DECLARE_ACCUMULATORS(binding): the global buffer `accum` and the
// workgroup-shared `s_acc`. It then adds with add_global / add_shared.
#ifndef TFMATCH_FIXED_POINT_ACCUMULATORS_GLSL
#define TFMATCH_FIXED_POINT_ACCUMULATORS_GLSL

#include "fixed_point.glsl"

#ifdef TFM_INT64
#define Fx uint64_t
#define FX_ZERO uint64_t(0)
#define TFM_DECLARE_ACCUMULATORS(b_)                                          \
  layout(std430, binding = b_) buffer Accum { uint64_t accum[]; };            \
  shared uint64_t s_acc[SHARED_SLOTS];
// floor(c 2^32) for 0 <= c < 2^32, the same integer as fx_from_float, formed the same way: whole
// and fraction each converted to 32 bits. (uint64_t(c * 2^32) is the same number, but a float
// to 64-bit conversion has no vector instruction on x86 without AVX-512: CPU devices converted
// lane by lane, a third of the assembly's time on lavapipe.)
Fx fx_term(float c) {
  const uvec2 v = fx_from_float(c);
  return uint64_t(v.x) | (uint64_t(v.y) << 32);
}
// v (|v| < 2^31) in two's complement, truncated towards zero like fx_from_signed.
Fx fx_signed_term(float v) {
  const uint64_t m = uint64_t(abs(v) * TFM_FIXED_ONE);
  return v < 0.0 ? uint64_t(0) - m : m;
}
void fx_sum(inout Fx a, Fx v) { a += v; }
// `voxels` whole units.
Fx fx_count(uint voxels) { return uint64_t(voxels) << 32; }
#define TFM_ADD_GLOBAL(k, v) { const Fx v_ = (v); if (v_ != FX_ZERO) atomicAdd(accum[k], v_); }
#define TFM_ADD_SHARED(k, v) { const Fx v_ = (v); if (v_ != FX_ZERO) atomicAdd(s_acc[k], v_); }
#define TFM_SHARED_TOTAL(k) s_acc[k]
#define TFM_ZERO_SHARED(k) s_acc[k] = FX_ZERO
#else
#define Fx uvec2
#define FX_ZERO uvec2(0u)
#define TFM_DECLARE_ACCUMULATORS(b_)                                          \
  layout(std430, binding = b_) buffer Accum { uint accum[]; };                \
  shared uint s_acc[2u * SHARED_SLOTS];
Fx fx_term(float c) { return fx_from_float(c); }
Fx fx_signed_term(float v) { return fx_from_signed(v); }
void fx_sum(inout Fx a, Fx v) { fx_add(a, v); }
Fx fx_count(uint voxels) { return uvec2(0u, voxels); }
#define TFM_ADD_GLOBAL(k, v) FX_ATOMIC_ADD(accum, (k), (v))
#define TFM_ADD_SHARED(k, v) FX_ATOMIC_ADD(s_acc, (k), (v))
#define TFM_SHARED_TOTAL(k) uvec2(s_acc[2u * (k)], s_acc[2u * (k) + 1u])
#define TFM_ZERO_SHARED(k) { s_acc[2u * (k)] = 0u; s_acc[2u * (k) + 1u] = 0u; }
#endif

// Zeroes `slots` shared accumulators; every invocation of the workgroup must call it.
#define TFM_SHARED_ACCUMULATORS_ZERO(slots)                                               \
  {                                                                                       \
    for (uint k_ = gl_LocalInvocationIndex; k_ < (slots); k_ += gl_WorkGroupSize.x)        \
      TFM_ZERO_SHARED(k_);                                                                \
    /* The zeroed slots are visible to the workgroup before any invocation adds to them. */ \
    memoryBarrierShared();                                                                \
    barrier();                                                                            \
  }

// Adds the workgroup's `slots` shared totals to the global accumulators once each; every
// invocation of the workgroup must call it.
#define TFM_SHARED_ACCUMULATORS_FLUSH(slots)                                              \
  {                                                                                       \
    /* Every shared add of this workgroup is complete before its totals are read. */      \
    memoryBarrierShared();                                                                \
    barrier();                                                                            \
    for (uint k_ = gl_LocalInvocationIndex; k_ < (slots); k_ += gl_WorkGroupSize.x)        \
      TFM_ADD_GLOBAL(k_, TFM_SHARED_TOTAL(k_))                                            \
  }

#endif
