// Pearson's correlation coefficient between the reference series x and each voxel's series y,
// one invocation per voxel for every M: two passes over the members (the mean of y, then the
// centred sums) need no storage, and neighbouring invocations read neighbouring addresses of the
// member-major chunk. x arrives centred, with sum (x - mean x)^2 (computed on the host in double).
// Sums are compensated (Kahan, `precise` keeps the compiler from reassociating them), so the
// error does not grow with M.
#version 450
#extension GL_GOOGLE_include_directive : require
#define CORR_REGIONS 0
#include "correlation_common.glsl"

// sum += term, carrying the rounding error in `carry`.
void kahan_add(inout float sum, inout float carry, float term) {
  precise float y = term - carry;
  precise float t = sum + y;
  precise float c = (t - sum) - y;
  carry = c;
  sum = t;
}

void main() {
  const uint m_count = pc.member_count;
  const uint v = corr_voxel();
  if (v >= pc.voxel_count) return;  // uniform across a workgroup per voxel
  vec4 stats = CORR_STATS_EMPTY;
  float sum = 0.0, carry = 0.0;
  for (uint m = 0u; m < m_count; ++m) {
    const float y = series_value(v, m);
    stats = corr_combine(stats, corr_stats_term(y));
    kahan_add(sum, carry, y);
  }
  if (corr_special_case(v, stats, CORR_NAN)) return;
  const float mean = sum / float(m_count);
  float sxy = 0.0, sxy_carry = 0.0, syy = 0.0, syy_carry = 0.0;
  for (uint m = 0u; m < m_count; ++m) {
    precise float d = series_value(v, m) - mean;
    precise float dd = d * d;
    precise float xd = ref_values[m] * d;
    kahan_add(sxy, sxy_carry, xd);
    kahan_add(syy, syy_carry, dd);
  }
  // The product of the two norms, not of the two sums: that could overflow float.
  const float r = sxy / (sqrt(pc.ref_norm) * sqrt(syy));
  corr_write(v, clamp(r, -1.0, 1.0));
}
