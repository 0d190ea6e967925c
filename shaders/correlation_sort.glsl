// Sorting and searching a voxel's series in its shared-memory regions (correlation_common.glsl):
// a stable bottom-up merge sort that counts inversions, and binary searches on the sorted values.
//
// Each merge level is split by output position ("merge path"): an invocation finds where its
// tile of outputs starts in the two runs by one binary search, then merges the tile
// sequentially. One invocation per voxel has a single tile (the whole level), so both strategies
// run the same code; a level costs O(M + T log M) for T invocations, O(M log M) in all.
#ifndef TFMATCH_CORRELATION_SORT_GLSL
#define TFMATCH_CORRELATION_SORT_GLSL

// Does element a (value va at position pa of the sequence) stay before element b of the right
// run in a stable merge? By value, or, with `by_group`, by (x tie group, value): then a merge
// sorts each tie group of the reference by y (kendall). Runs are contiguous positions and the
// groups are contiguous too, so at every level an element's group is that of its position.
bool corr_keeps_order(float va, uint pa, float vb, uint pb, bool by_group) {
  if (by_group) {
    const uint ga = ref_group[pa], gb = ref_group[pb];
    if (ga != gb) return ga < gb;
  }
  return va <= vb;
}

// Outputs [d0, d1) of the merge of the block at b0 of region `src` (left run of len_l values,
// then right run of len_r) into the same positions of region `dst`. Returns the inversions these
// outputs close: a right value taken while i left values remain passes len_l - i larger ones.
uint corr_merge_tile(uint src, uint dst, uint b0, uint len_l, uint len_r, uint d0, uint d1, bool by_group) {
  const uint left = src + b0, right = src + b0 + len_l;
  // The left values among the first d0 outputs: the first i with right[d0 - 1 - i] before left[i].
  uint lo = d0 > len_r ? d0 - len_r : 0u, hi = min(d0, len_l);
  while (lo < hi) {
    const uint mid = (lo + hi) >> 1u, rj = d0 - 1u - mid;
    if (corr_keeps_order(s_work[left + mid], b0 + mid, s_work[right + rj], b0 + len_l + rj, by_group))
      lo = mid + 1u;
    else
      hi = mid;
  }
  uint i = lo, j = d0 - lo, inversions = 0u;
  for (uint d = d0; d < d1; ++d) {
    const bool take_left = j >= len_r ||
        (i < len_l && corr_keeps_order(s_work[left + i], b0 + i, s_work[right + j], b0 + len_l + j, by_group));
    if (take_left) {
      s_work[dst + b0 + d] = s_work[left + i];
      ++i;
    } else {
      s_work[dst + b0 + d] = s_work[right + j];
      ++j;
      inversions += len_l - i;
    }
  }
  return inversions;
}

// Sorts the n values of region `a` (region `b` is scratch) and returns the region that holds
// them sorted; `inversions` gets this invocation's share of the pairs p < q with value_p >
// value_q (with `by_group`: of the pairs out of (group, value) order). In the workgroup strategy
// every invocation must call it (barriers) after the values are in place and visible.
uint corr_sort(uint a, uint b, uint n, bool by_group, out uint inversions) {
  inversions = 0u;
  // This invocation's tile of outputs at every level: all of them, or an aligned power-of-two
  // share of the workgroup's. Levels whose blocks fit in a tile read only what this invocation
  // wrote, so only the levels above need barriers.
  uint tile = n, t0 = 0u, t1 = n;
  if (GROUP_PER_VOXEL) {
    const uint per = (n + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
    tile = per <= 1u ? 1u : 1u << (findMSB(per - 1u) + 1);
    t0 = min(gl_LocalInvocationIndex * tile, n);
    t1 = min(t0 + tile, n);
  }
  for (uint w = 1u; w < n; w <<= 1u) {
    for (uint pos = t0; pos < t1;) {
      const uint b0 = pos / (2u * w) * (2u * w);
      const uint len_l = min(w, n - b0), len_r = min(w, n - b0 - len_l);
      const uint end = min(t1, b0 + len_l + len_r);
      inversions += corr_merge_tile(a, b, b0, len_l, len_r, pos - b0, end - b0, by_group);
      pos = end;
    }
    // The next level's blocks (4w wide) reach into other tiles, or this was the last level: the
    // level is complete before anyone reads it (the branch is uniform).
    if (GROUP_PER_VOXEL && (4u * w > tile || 2u * w >= n)) {
      memoryBarrierShared();
      barrier();
    }
    const uint t = a;
    a = b;
    b = t;
  }
  return a;
}

// First q in [lo, hi) of the sorted region `r` with value >= x (lower bound) or > x (upper bound).
uint corr_lower_bound(uint r, uint lo, uint hi, float x) {
  while (lo < hi) {
    const uint mid = (lo + hi) >> 1u;
    if (s_work[r + mid] < x) lo = mid + 1u; else hi = mid;
  }
  return lo;
}

uint corr_upper_bound(uint r, uint lo, uint hi, float x) {
  while (lo < hi) {
    const uint mid = (lo + hi) >> 1u;
    if (s_work[r + mid] <= x) lo = mid + 1u; else hi = mid;
  }
  return lo;
}

// Pairs of equal values among the n sorted values of region `r` that this invocation accounts
// for: each position q adds the equal values before it (a run of t equal values adds t(t-1)/2).
// With `by_group`, runs end at the x tie groups (region sorted by group, then value).
uint corr_tied_pairs(uint r, uint n, bool by_group) {
  uint pairs = 0u;
  CORR_FOR_EACH(q, n) {
    const uint first = by_group ? ref_group[q] : 0u;
    pairs += q - corr_lower_bound(r, first, q, s_work[r + q]);
  }
  return pairs;
}

#endif
