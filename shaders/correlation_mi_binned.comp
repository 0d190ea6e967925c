// Binned mutual information (nats) between the reference series x and each voxel's series y:
// B equal-width bins over each series' own min..max, bin = min(floor((v - min) B / (max - min)),
// B - 1) (multiplied before dividing: a value on an edge in exact arithmetic lands on it, as long
// as v - min and (v - min) B are exact), and
//   MI = ln M + (1/M) sum_m [ln c_xy(m) - ln c_x(m) - ln c_y(m)],
// c_xy(m), c_x(m), c_y(m) the counts of member m's joint, x and y bins (the plug-in estimate
// sum p_xy ln(p_xy / (p_x p_y)), summed per member so both strategies add the same terms).
// ln c comes from a table the host computes in double. One invocation per voxel counts by
// comparing every pair of members while M <= 32 (at most 1024 comparisons of bin codes kept in
// its shared-memory slice: on lavapipe 1.3x faster than what follows at M = 10); up to M = 4096
// it takes the members grouped by x bin (the host's order: x's bins are the same at every voxel)
// and counts, in its slice of s_joint, each y bin over all members (c_y, low 16 bits of a word)
// and within the current x bin (c_xy, high 16 bits): O(M + bins) per voxel, every member's terms
// in that order. One workgroup per voxel (more members) builds the joint histogram in shared
// memory with integer atomics (exact whatever the order).
#version 450
#extension GL_GOOGLE_include_directive : require
#define CORR_REGIONS 1
#include "correlation_common.glsl"

shared uint s_joint[TFM_CORR_JOINT_WORDS];
shared uint s_marginal[2u * TFM_CORR_MAX_BINS];  // x bins, then y bins

// The bin of `value` in a series with minimum lo and range hi - lo > 0: the largest b < B with
// b * range <= (value - lo) * B, each side one correctly rounded float product. No division
// decides it: Vulkan allows a float division 2.5 ulp, so a value on a bin edge fell into the
// neighbouring bin on one device and not on another (NVIDIA 580 against the CPU: MI off by
// 0.017 at 100 members). The quotient only guesses, within one bin; the products decide, the
// same on every device and in the CPU peer (host/reference/correlation_field_cpu.cpp).
uint bin_of(float value, float lo, float range) {
  const uint bins = pc.param;
  precise float scaled = (value - lo) * float(bins);
  uint b = min(uint(scaled / range), bins - 1u);
  precise float edge = float(b) * range;
  precise float next = float(b + 1u) * range;
  if (b > 0u && edge > scaled) b -= 1u;
  else if (b + 1u < bins && next <= scaled) b += 1u;
  return b;
}

void main() {
  const uint n = pc.member_count, bins = pc.param;
  const float x_range = pc.ref_hi - pc.ref_lo;
  if (GROUP_PER_VOXEL) {
    for (uint c = gl_LocalInvocationIndex; c < bins * bins; c += gl_WorkGroupSize.x) s_joint[c] = 0u;
    for (uint c = gl_LocalInvocationIndex; c < 2u * TFM_CORR_MAX_BINS; c += gl_WorkGroupSize.x) s_marginal[c] = 0u;
    // The histogram is clear before any invocation adds to it.
    memoryBarrierShared();
    barrier();
  }
  const uint v = corr_voxel();
  if (v >= pc.voxel_count) return;  // uniform across a workgroup per voxel
  vec4 part = CORR_STATS_EMPTY;
  CORR_FOR_EACH(m, n) part = corr_combine(part, corr_finite_stats_term(series_value(v, m)));
  const vec4 stats = corr_total(part);
  if (corr_special_case(v, stats, 0.0)) return;
  const float y_lo = stats.y, y_range = stats.z - stats.y;
  float sum = 0.0;
  if (GROUP_PER_VOXEL) {
    CORR_FOR_EACH(m, n) {
      const uint bx = bin_of(REF_VALUE(m), pc.ref_lo, x_range), by = bin_of(series_value(v, m), y_lo, y_range);
      atomicAdd(s_joint[bx * bins + by], 1u);
      atomicAdd(s_marginal[bx], 1u);
      atomicAdd(s_marginal[TFM_CORR_MAX_BINS + by], 1u);
    }
    // The histogram is complete before it is read.
    memoryBarrierShared();
    barrier();
    CORR_FOR_EACH(m, n) {
      const uint bx = bin_of(REF_VALUE(m), pc.ref_lo, x_range), by = bin_of(series_value(v, m), y_lo, y_range);
      sum += count_table[s_joint[bx * bins + by]] - count_table[s_marginal[bx]] -
             count_table[s_marginal[TFM_CORR_MAX_BINS + by]];
    }
  } else if (n <= TFM_CORR_INVOCATION_MAX_MEMBERS) {
    // Bin codes x * TFM_CORR_MAX_BINS + y, exact as floats.
    const uint codes = corr_region(0u);
    for (uint m = 0u; m < n; ++m) {
      const uint bx = bin_of(REF_VALUE(m), pc.ref_lo, x_range), by = bin_of(series_value(v, m), y_lo, y_range);
      s_work[codes + m] = float(bx * TFM_CORR_MAX_BINS + by);
    }
    for (uint m = 0u; m < n; ++m) {
      const uint code = uint(s_work[codes + m]);
      uint joint = 0u, cx = 0u, cy = 0u;
      for (uint l = 0u; l < n; ++l) {
        const uint other = uint(s_work[codes + l]);
        joint += other == code ? 1u : 0u;
        cx += other / TFM_CORR_MAX_BINS == code / TFM_CORR_MAX_BINS ? 1u : 0u;
        cy += other % TFM_CORR_MAX_BINS == code % TFM_CORR_MAX_BINS ? 1u : 0u;
      }
      sum += count_table[joint] - count_table[cx] - count_table[cy];
    }
  } else {
    const uint slice = gl_LocalInvocationIndex * TFM_CORR_BIN_STRIDE;
    for (uint b = 0u; b < bins; ++b) s_joint[slice + b] = 0u;
    for (uint m = 0u; m < n; ++m) s_joint[slice + bin_of(series_value(v, m), y_lo, y_range)] += 1u;
    // The x bins' groups of positions [p, end) in order; each group's counts cleared after it.
    for (uint p = 0u; p < n;) {
      const uint end = ref_group[p];
      for (uint q = p; q < end; ++q) s_joint[slice + bin_of(series_value(v, ref_order[q]), y_lo, y_range)] += 0x10000u;
      const float ln_cx = count_table[end - p];
      for (uint q = p; q < end; ++q) {
        const uint counts = s_joint[slice + bin_of(series_value(v, ref_order[q]), y_lo, y_range)];
        sum += count_table[counts >> 16u] - ln_cx - count_table[counts & 0xffffu];
      }
      for (uint q = p; q < end; ++q) s_joint[slice + bin_of(series_value(v, ref_order[q]), y_lo, y_range)] &= 0xffffu;
      p = end;
    }
  }
  const float mi = pc.mi_offset + corr_total(vec4(sum, 0.0, 0.0, 0.0)).x / float(n);
  // The plug-in estimate is >= 0; only rounding of the sum can take it below.
  corr_write(v, max(mi, 0.0));
}
