// Kraskov-Stoegbauer-Grassberger mutual information (estimator 1, nats) between the reference
// series x and each voxel's series y, or its coefficient sqrt(1 - exp(-2 max(MI, 0))):
//   MI = digamma(k) + digamma(M) - (1/M) sum_i [digamma(n_x(i) + 1) + digamma(n_y(i) + 1)],
// eps_i the max-norm distance from point i to its k-th nearest neighbour (i excluded), n_x(i) and
// n_y(i) the points other than i strictly closer than eps_i in x and in y. No jitter: ties are
// kept as they are, and the result has the same bits on every run.
//
// Per voxel: x sorted (host, once for all voxels), y in x order and y sorted (merge sort in
// shared memory). eps_i: walk outwards from i in x order, nearer x first, keeping the k smallest
// distances, and stop once |dx| alone reaches the k-th (the cost is the points in the band
// |dx| < eps_i, about sqrt(k M) for independent series, k for strongly dependent ones). n_x and
// n_y: two binary searches each in the sorted x and sorted y. digamma comes from a table the
// host computes in double.
#version 450
#extension GL_GOOGLE_include_directive : require
#define CORR_REGIONS 3
#include "correlation_common.glsl"
#include "correlation_sort.glsl"

layout(constant_id = TFM_CORR_SPEC_COEFFICIENT) const bool COEFFICIENT = false;

// eps of the point at x-order position p: xs holds x sorted, yx y in the same order.
float kth_neighbour_distance(uint xs, uint yx, uint n, uint p, uint k) {
  float best[TFM_CORR_MAX_K];  // the smallest distances so far, ascending
  uint found = 0u;
  const float x = s_work[xs + p], y = s_work[yx + p];
  uint left = p, right = p + 1u;  // the next candidates are left - 1 and right
  while (left > 0u || right < n) {
    const float dl = left > 0u ? x - s_work[xs + left - 1u] : CORR_INF;
    const float dr = right < n ? s_work[xs + right] - x : CORR_INF;
    const bool go_left = left > 0u && (right >= n || dl <= dr);
    const float dx = go_left ? dl : dr;
    // Every point further out in x is at least dx away: none comes closer than the k-th so far.
    if (found == k && dx >= best[k - 1u]) break;
    uint q;
    if (go_left) {
      --left;
      q = left;
    } else {
      q = right;
      ++right;
    }
    const float d = max(dx, abs(s_work[yx + q] - y));
    if (found < k || d < best[k - 1u]) {
      uint j = found < k ? found++ : k - 1u;
      for (; j > 0u && best[j - 1u] > d; --j) best[j] = best[j - 1u];
      best[j] = d;
    }
  }
  return best[k - 1u];
}

// Values of the sorted region r strictly within eps of c: |s - c| < eps, with s - c rounded as
// in kth_neighbour_distance (monotone in s, so the values form one run).
uint count_within(uint r, uint n, float c, float eps) {
  uint lo = 0u, hi = n;
  while (lo < hi) {
    const uint mid = (lo + hi) >> 1u;
    if (s_work[r + mid] - c > -eps) hi = mid; else lo = mid + 1u;
  }
  const uint first = lo;
  hi = n;
  while (lo < hi) {
    const uint mid = (lo + hi) >> 1u;
    if (s_work[r + mid] - c >= eps) hi = mid; else lo = mid + 1u;
  }
  return lo - first;
}

void main() {
  const uint n = pc.member_count, k = pc.param;
  const uint v = corr_voxel();
  if (v >= pc.voxel_count) return;  // uniform across a workgroup per voxel
  const uint r0 = corr_region(0u), yx = corr_region(1u), r2 = corr_region(2u);
  vec4 part = CORR_STATS_EMPTY;
  CORR_FOR_EACH(p, n) {
    s_work[yx + p] = series_value(v, ref_order[p]);
    const float y = series_value(v, p);
    s_work[r2 + p] = y;
    part = corr_combine(part, corr_finite_stats_term(y));  // an infinite member: no neighbours, no value
  }
  if (corr_special_case(v, corr_total(part), 0.0)) return;
  uint unused;
  const uint ys = corr_sort(r2, r0, n, false, unused);
  // x goes to the sort's other region, free once the sort's last barrier has passed.
  const uint xs = ys == r0 ? r2 : r0;
  CORR_FOR_EACH(p, n) s_work[xs + p] = REF_VALUE(p);
  if (GROUP_PER_VOXEL) {
    // x is in place before any invocation searches it.
    memoryBarrierShared();
    barrier();
  }
  float sum = 0.0;
  CORR_FOR_EACH(p, n) {
    const float eps = kth_neighbour_distance(xs, yx, n, p, k);
    // Both counts include point p itself when eps > 0 (none do when eps = 0).
    const uint self = eps > 0.0 ? 1u : 0u;
    const uint nx = count_within(xs, n, s_work[xs + p], eps) - self;
    const uint ny = count_within(ys, n, s_work[yx + p], eps) - self;
    sum += count_table[nx + 1u] + count_table[ny + 1u];
  }
  const float mi = pc.mi_offset - corr_total(vec4(sum, 0.0, 0.0, 0.0)).x / float(n);
  corr_write(v, COEFFICIENT ? sqrt(1.0 - exp(-2.0 * max(mi, 0.0))) : mi);
}
