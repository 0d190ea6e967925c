// Shared GLSL helpers: the field-to-TF mapping of DESIGN.md and deterministic fixed-point sums.
#ifndef TFMATCH_TF_COMMON_GLSL
#define TFMATCH_TF_COMMON_GLSL

// Node-aligned TF coordinate: x = clamp((v - lo) * scale, 0, n-1), j = min(floor(x), n-2),
// w = x - j. `precise` forbids fused or reordered arithmetic, so j and w are bit-identical to
// the same IEEE float32 operations on the host (host/field_mapping.h mirrors them).
// Returns false for NaN ("no data").
bool tf_coordinate(float v, float lo, float scale, uint n, out uint j, out float w) {
  if (isnan(v)) { j = 0u; w = 0.0; return false; }
  precise float x = clamp((v - lo) * scale, 0.0, float(n - 1u));
  float jf = min(floor(x), float(n - 2u));
  j = uint(jf);
  precise float wf = x - jf;
  w = wf;
  return true;
}

// Converts a non-negative value below 2^32 to 32.32 fixed point. Exact for every float >= 2^-9;
// smaller values lose less than 2^-32 (truncation).
uvec2 fx_from_float(float c) {
  float whole = floor(c);
  return uvec2(uint((c - whole) * TFM_FIXED_ONE), uint(whole));
}

// acc += v on a thread-private 64-bit fixed-point number.
void fx_add(inout uvec2 acc, uvec2 v) {
  uint lo = acc.x + v.x;
  acc.y += v.y + (lo < acc.x ? 1u : 0u);
  acc.x = lo;
}

// Atomic 64-bit add into words arr[2k] (low) and arr[2k+1] (high) using 32-bit atomics: the
// carry out of the low word is detected from the value the atomic returns, so each carry is
// added exactly once and the final 64-bit total is exact whatever the interleaving.
#define FX_ATOMIC_ADD(arr, k, v)                                               \
  {                                                                            \
    uvec2 fx_v_ = (v);                                                         \
    if ((fx_v_.x | fx_v_.y) != 0u) {                                           \
      uint fx_old_ = atomicAdd(arr[2u * (k)], fx_v_.x);                        \
      uint fx_hi_ = fx_v_.y + ((fx_old_ + fx_v_.x) < fx_old_ ? 1u : 0u);       \
      if (fx_hi_ != 0u) atomicAdd(arr[2u * (k) + 1u], fx_hi_);                 \
    }                                                                          \
  }

#endif
