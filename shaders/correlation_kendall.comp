// Kendall's tau-b between the reference series x and each voxel's series y, with every tie term
// (as scipy.stats.kendalltau by default). The host sorts x once (ref_order: the member at each
// position in x order, ref_group: where its x tie group starts), and per voxel y is laid out in x
// order. Up to TFM_CORR_KENDALL_PAIRS_MAX_MEMBERS every pair of positions p < q is compared
// (x_p < x_q unless they share a tie group; with one workgroup per voxel the whole workgroup reads
// the same q at once, no barriers). Beyond, in O(M log M) by Knight's method: when x has ties, a
// first merge sort orders each tie group by y (and the pairs tied in both x and y are counted
// there); then a merge sort by y counts the discordant pairs as inversions, and the sorted y
// gives the pairs tied in y.
//   tau_b = (n0 - n1 - n2 + n3 - 2 discordant) / sqrt((n0 - n1)(n0 - n2)),
// n0 = M(M-1)/2, n1 / n2 / n3 the pairs tied in x / y / both. All counts are exact integers.
#version 450
#extension GL_GOOGLE_include_directive : require
#define CORR_REGIONS 2
#include "correlation_common.glsl"
#include "correlation_sort.glsl"

// tau_b from the voxel's totals t: (discordant pairs, pairs tied in y, pairs tied in both).
void write_tau(uint v, uint n, uvec4 t) {
  const int n0 = int(n * (n - 1u) / 2u), n1 = int(pc.ref_tied_pairs);
  const int numerator = n0 - n1 - int(t.y) + int(t.z) - 2 * int(t.x);
  const float tau = float(numerator) / (sqrt(float(n0 - n1)) * sqrt(float(n0 - int(t.y))));
  corr_write(v, clamp(tau, -1.0, 1.0));
}

void main() {
  const uint n = pc.member_count;
  const bool x_ties = (pc.flags & TFM_CORR_FLAG_REF_TIES) != 0u;
  const uint v = corr_voxel();
  if (v >= pc.voxel_count) return;  // uniform across a workgroup per voxel
  const uint a = corr_region(0u), b = corr_region(1u);
  corr_clear_counts();
  vec4 part = CORR_STATS_EMPTY;
  CORR_FOR_EACH(p, n) {
    const float y = series_value(v, ref_order[p]);
    s_work[a + p] = y;
    part = corr_combine(part, corr_stats_term(y));
  }
  if (corr_special_case(v, corr_total(part), CORR_NAN)) return;
  if (n <= TFM_CORR_KENDALL_PAIRS_MAX_MEMBERS) {
    // corr_total's barrier made the whole series visible (one invocation per voxel wrote its own).
    // The same integers as the sorts count.
    uint discordant = 0u, y_tied = 0u, both_tied = 0u;
    CORR_FOR_EACH(p, n) {
      const float y = s_work[a + p];
      const uint group = ref_group[p];
      // A workgroup reads the same q at once, so each invocation runs over all of them; one
      // invocation per voxel starts past p (p is the same in every invocation).
      for (uint q = GROUP_PER_VOXEL ? 0u : p + 1u; q < n; ++q) {
        const float other = s_work[a + q];
        const bool later = q > p, same_x = ref_group[q] == group;
        discordant += later && !same_x && other < y ? 1u : 0u;
        y_tied += later && other == y ? 1u : 0u;
        both_tied += later && same_x && other == y ? 1u : 0u;
      }
    }
    write_tau(v, n, corr_count_total(uvec4(discordant, y_tied, both_tied, 0u)));
    return;
  }
  uint seq = a, scratch = b, unused, both_tied = 0u;
  if (x_ties) {
    // Knight's order: x, then y within x ties. Its equal neighbours are the pairs tied in both.
    seq = corr_sort(a, b, n, true, unused);
    scratch = seq == a ? b : a;
    both_tied = corr_tied_pairs(seq, n, true);
    if (GROUP_PER_VOXEL) {
      // Every invocation has finished reading `seq` before the next sort rewrites it.
      barrier();
    }
  }
  uint discordant;
  const uint sorted = corr_sort(seq, scratch, n, false, discordant);
  write_tau(v, n, corr_count_total(uvec4(discordant, corr_tied_pairs(sorted, n, false), both_tied, 0u)));
}
