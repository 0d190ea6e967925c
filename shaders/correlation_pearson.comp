// Pearson's correlation coefficient between the reference series x and each voxel's series y,
// one invocation per voxel for every M, in one pass over the members where that is accurate.
// x arrives centred, with sum (x - mean x)^2 (computed on the host in double). Neighbouring
// invocations read neighbouring addresses of the member-major series.
//
// One pass: sums of d = y - y0, shifted by the voxel's first member, d^2 and x d. Then
//   syy = sum d^2 - (sum d)^2 / M,   sxy = sum x d   (sum x = 0 up to x's rounding),
// and the differences d are exact to a rounding of the series' spread, not of its magnitude.
// What the shift costs is the cancellation in syy: it errs by about eps (sum d^2), and
// sum d^2 = syy + M (mean - y0)^2. While M (mean - y0)^2 <= TFM_CORR_PEARSON_SHIFT_LIMIT syy
// (the first member within 4 standard deviations of the mean for the limit 16: all but 6e-5 of
// Gaussian series) the error stays a fixed number of ulps whatever M (error_bound in
// kernels/correlation.cpp states it); beyond, the voxel takes a second pass about its mean,
// as the two-pass formula. Sums are compensated (Kahan, `precise` keeps the compiler from
// reassociating them), so their error does not grow with M.
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
  const float y0 = series_value(v, 0u);
  // A member without a value, NaN or ±Inf (an infinite member makes the mean infinite: NaN, as in
  // the double reference), and a member unlike the first (else the series is constant): two
  // flags, cheaper than the other measures' min/max statistics (on lavapipe 4 % fewer of this
  // kernel's instructions, docs/benchmarks.md). any(), not ||, which glslang compiles to a branch.
  bool no_value = no_data(y0), varies = false;
  float sd = 0.0, sd_carry = 0.0, sdd = 0.0, sdd_carry = 0.0, sxd = 0.0, sxd_carry = 0.0;
  for (uint m = 1u; m < m_count; ++m) {
    const float y = series_value(v, m);
    no_value = any(bvec2(no_value, no_data(y)));
    varies = any(bvec2(varies, y != y0));
    precise float d = y - y0;
    precise float dd = d * d;
    precise float xd = REF_VALUE(m) * d;
    kahan_add(sd, sd_carry, d);
    kahan_add(sdd, sdd_carry, dd);
    kahan_add(sxd, sxd_carry, xd);
  }
  if (corr_special_result(v, no_value, varies, CORR_NAN)) return;
  // mean - y0, and M (mean - y0)^2.
  precise float offset = sd / float(m_count);
  precise float spread_of_shift = offset * sd;
  precise float syy = sdd - spread_of_shift;
  float sxy = sxd;
  // Negated so that NaN (an infinite member) takes the second pass too, as the two-pass formula.
  if (!(spread_of_shift <= TFM_CORR_PEARSON_SHIFT_LIMIT * syy)) {
    const float mean = y0 + offset;
    sxy = 0.0;
    syy = 0.0;
    float sxy_carry = 0.0, syy_carry = 0.0;
    for (uint m = 0u; m < m_count; ++m) {
      precise float d = series_value(v, m) - mean;
      precise float dd = d * d;
      precise float xd = REF_VALUE(m) * d;
      kahan_add(sxy, sxy_carry, xd);
      kahan_add(syy, syy_carry, dd);
    }
  }
  // The product of the two norms, not of the two sums: that could overflow float.
  const float r = sxy / (sqrt(pc.ref_norm) * sqrt(syy));
  corr_write(v, clamp(r, -1.0, 1.0));
}
