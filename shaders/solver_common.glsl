// GLSL helpers of the matrix-free solvers: splitting a stored TF coordinate, signed 32.32
// fixed-point accumulation (deterministic sums of residuals and gradients) and its decoding.
#ifndef TFMATCH_SOLVER_COMMON_GLSL
#define TFMATCH_SOLVER_COMMON_GLSL

// j = min(floor(x), n-2), w = x - j: the second half of tf_coordinate(), so a coordinate stored
// by sparse_prepare gives bit-identical j and w. Returns false for TFM_NO_DATA.
bool split_coordinate(float x, uint n, out uint j, out float w) {
  if (!(x >= 0.0)) { j = 0u; w = 0.0; return false; }
  float jf = min(floor(x), float(n - 2u));
  j = uint(jf);
  precise float wf = x - jf;
  w = wf;
  return true;
}

// Adds a signed float to signed slot k (TFM_SIGNED_SLOT_WORDS words: positive total, then the
// total of negated negative terms). Zero adds nothing.
#define FX_SIGNED_ATOMIC_ADD(arr, k, value)                                  \
  {                                                                          \
    float fx_s_ = (value);                                                   \
    if (fx_s_ > 0.0) {                                                       \
      FX_ATOMIC_ADD(arr, 2u * (k), fx_from_float(fx_s_))                     \
    } else if (fx_s_ < 0.0) {                                                \
      FX_ATOMIC_ADD(arr, 2u * (k) + 1u, fx_from_float(-fx_s_))               \
    }                                                                        \
  }

// Value of a non-negative 32.32 number (lo, hi) as float.
float fx_to_float(uvec2 v) { return float(v.y) + float(v.x) * (1.0 / TFM_FIXED_ONE); }

// (pos - neg) as float: the difference is formed exactly in 64-bit integer arithmetic (with a
// borrow), so cancelling totals (a residual orthogonal to S) lose nothing before the rounding.
float fx_signed_to_float(uvec2 pos, uvec2 neg) {
  bool negative = neg.y > pos.y || (neg.y == pos.y && neg.x > pos.x);
  uvec2 a = negative ? neg : pos;
  uvec2 b = negative ? pos : neg;
  uint lo = a.x - b.x;
  uint hi = a.y - b.y - (a.x < b.x ? 1u : 0u);
  float magnitude = fx_to_float(uvec2(lo, hi));
  return negative ? -magnitude : magnitude;
}

#endif
