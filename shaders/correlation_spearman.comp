// Spearman's rank correlation between the reference series x and each voxel's series y: the
// Pearson coefficient of fractional ranks (ties get their mean rank): 2 rank = (members below) +
// (members not above) + 1, counted by comparing every pair up to
// TFM_CORR_SPEARMAN_PAIRS_MAX_MEMBERS (with one workgroup per voxel the whole workgroup reads the
// same member at once, no barriers), or from two binary searches in the series merge-sorted in
// shared memory beyond (the same integers). Centred doubled ranks c = 2 rank - (M + 1) are
// integers, so the sums of c_x c_y and c_y^2 are exact (64-bit, shaders/fixed_point.glsl); x's
// centred doubled ranks and their sum of squares come from the host.
#version 450
#extension GL_GOOGLE_include_directive : require
#define CORR_REGIONS 2
#include "correlation_common.glsl"
#include "correlation_sort.glsl"
#include "fixed_point.glsl"

// 64-bit workgroup totals: slot 0 sum c_x c_y (two's complement), slot 1 sum c_y^2.
shared uint s_wide[2u * TFM_FIXED_SLOT_WORDS];

// The workgroup's exact totals of two 64-bit integers (each invocation's own in one invocation
// per voxel). s_wide is cleared at the start of the voxel, before its first barrier.
void wide_totals(inout uvec2 a, inout uvec2 b) {
  if (!GROUP_PER_VOXEL) return;
  FX_ATOMIC_ADD(s_wide, 0u, a)
  FX_ATOMIC_ADD(s_wide, 1u, b)
  // Every add is done before the totals are read.
  memoryBarrierShared();
  barrier();
  a = uvec2(s_wide[0], s_wide[1]);
  b = uvec2(s_wide[2], s_wide[3]);
}

// Signed 64-bit integer in two's complement (|v| < 2^53) to float.
float wide_to_float(uvec2 v) { return fx_signed_to_float(v) * TFM_FIXED_ONE; }

// Member m's terms of the exact sums: c_x c_y and c_y^2, c_y its centred doubled rank.
void add_rank_terms(uint m, int cy, inout uvec2 sxy, inout uvec2 syy) {
  const int p = int(REF_VALUE(m)) * cy;
  fx_add(sxy, p < 0 ? fx_negate(uvec2(uint(-p), 0u)) : uvec2(uint(p), 0u));
  fx_add(syy, uvec2(uint(cy * cy), 0u));
}

void main() {
  const uint n = pc.member_count;
  const uint v = corr_voxel();
  if (v >= pc.voxel_count) return;  // uniform across a workgroup per voxel
  const uint a = corr_region(0u), b = corr_region(1u);
  if (GROUP_PER_VOXEL && gl_LocalInvocationIndex < 2u * TFM_FIXED_SLOT_WORDS) s_wide[gl_LocalInvocationIndex] = 0u;
  vec4 part = CORR_STATS_EMPTY;
  CORR_FOR_EACH(m, n) {
    const float y = series_value(v, m);
    s_work[a + m] = y;
    part = corr_combine(part, corr_stats_term(y));
  }
  if (corr_special_case(v, corr_total(part), CORR_NAN)) return;
  uvec2 sxy = uvec2(0u), syy = uvec2(0u);
  if (n <= TFM_CORR_SPEARMAN_PAIRS_MAX_MEMBERS) {
    // corr_total's barrier made the whole series visible (one invocation per voxel wrote its own).
    CORR_FOR_EACH(m, n) {
      const float y = s_work[a + m];
      uint below = 0u, not_above = 0u;
      for (uint l = 0u; l < n; ++l) {
        const float other = s_work[a + l];
        below += other < y ? 1u : 0u;
        not_above += other <= y ? 1u : 0u;
      }
      add_rank_terms(m, int(below + not_above + 1u) - int(n + 1u), sxy, syy);
    }
  } else {
    uint unused;
    const uint sorted = corr_sort(a, b, n, false, unused);
    CORR_FOR_EACH(m, n) {
      const float y = series_value(v, m);
      add_rank_terms(m, int(corr_lower_bound(sorted, 0u, n, y) + corr_upper_bound(sorted, 0u, n, y) + 1u) - int(n + 1u),
                     sxy, syy);
    }
  }
  wide_totals(sxy, syy);
  const float r = wide_to_float(sxy) / (sqrt(pc.ref_norm) * sqrt(wide_to_float(syy)));
  corr_write(v, clamp(r, -1.0, 1.0));
}
