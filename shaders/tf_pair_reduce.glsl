// The reduction of the kernels that scatter a signed vec4 pair per voxel to two TF entries
// (sparse_scatter: S^T r; gd_gradient: the gradient): lo to entry j and hi to entry j + 1 of 4N
// signed 32.32 fixed-point slots (slot 4j + c for channel c). Each term is converted on its own
// (fx_signed_term) and summed as an integer, so the totals are the same bits for every MODE,
// atomic width, chunking and workgroup count. MODE as in assemble_normal_equations.comp:
//   TFM_REDUCE_PRIVATE      each lane adds into its own histogram of 4N sums (no atomics, no
//                           branches: CPU devices), added to the global slots once at the end;
//   TFM_REDUCE_RUNS_SHARED  each lane sums the current entry pair in registers and adds the run
//   TFM_REDUCE_RUNS_GLOBAL  to shared (or global) slots when the pair changes (GPUs).
// The including shader declares the constants MODE, PRIVATE_BINS (N in private mode, else 0)
// and SHARED_SLOTS, includes fixed_point_accumulators.glsl and declares its accumulators, then
// calls pair_begin(), pair_add() per voxel and pair_end(n) once per invocation.
//
// Several sets (irls_assemble: three sums per entry and channel): the shader defines
// TFM_PAIR_SETS and TFM_PAIR_SET_STRIDE (the slots of one set, 4N) before including this file and
// adds with pair_add_set(s, ...), set 0 first for each voxel; set s owns slots s * stride + 4j + c.
// All sets of a voxel go to the same entry pair, so they share one run.
#ifndef TFMATCH_TF_PAIR_REDUCE_GLSL
#define TFMATCH_TF_PAIR_REDUCE_GLSL

#ifndef TFM_PAIR_SETS
#define TFM_PAIR_SETS 1u
#define TFM_PAIR_SET_STRIDE 0u
#endif

// PRIVATE: one histogram per set and channel, pair_hist<s>_<c>[j] (sets up to 3; a set the shader
// does not use gets one element it never touches). Twelve arrays of N rather than one of 12 N:
// lavapipe's compile time grows faster than linearly with a private array's size (see
// assemble_normal_equations.comp), and the adds index each array by j alone.
#define TFM_PAIR_HIST_SIZE(s) (uint(s) < TFM_PAIR_SETS ? PRIVATE_BINS + 1u : 1u)
#define TFM_PAIR_EACH_CHANNEL(M, s) M(s, 0) M(s, 1) M(s, 2) M(s, 3)
#define TFM_PAIR_EACH(M) TFM_PAIR_EACH_CHANNEL(M, 0) TFM_PAIR_EACH_CHANNEL(M, 1) TFM_PAIR_EACH_CHANNEL(M, 2)
#define TFM_PAIR_DECLARE(s, c) Fx pair_hist##s##_##c[TFM_PAIR_HIST_SIZE(s)];
TFM_PAIR_EACH(TFM_PAIR_DECLARE)
const uint tfm_pair_sets_at_most_3[TFM_PAIR_SETS <= 3u ? 1 : -1] = {0u};  // more sets need more arrays above
Fx pair_lo[4u * TFM_PAIR_SETS], pair_hi[4u * TFM_PAIR_SETS];  // run sums of entries pair_bin, pair_bin + 1
uint pair_bin;               // NO_PAIR between runs
const uint NO_PAIR = 0xFFFFFFFFu;

void pair_slot_add(uint k, Fx v) {
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_ADD_SHARED(k, v)
  else TFM_ADD_GLOBAL(k, v)
}

void pair_flush_run() {
  if (pair_bin == NO_PAIR) return;
  for (uint s = 0u; s < TFM_PAIR_SETS; ++s)
    for (uint c = 0u; c < 4u; ++c) {
      pair_slot_add(s * TFM_PAIR_SET_STRIDE + 4u * pair_bin + c, pair_lo[4u * s + c]);
      pair_slot_add(s * TFM_PAIR_SET_STRIDE + 4u * (pair_bin + 1u) + c, pair_hi[4u * s + c]);
      pair_lo[4u * s + c] = pair_hi[4u * s + c] = FX_ZERO;
    }
}

void pair_begin() {
  for (uint j = 0u; j < PRIVATE_BINS; ++j) {
#define TFM_PAIR_ZERO(s, c) if (uint(s) < TFM_PAIR_SETS) pair_hist##s##_##c[j] = FX_ZERO;
    TFM_PAIR_EACH(TFM_PAIR_ZERO)
  }
  for (uint k = 0u; k < 4u * TFM_PAIR_SETS; ++k) pair_lo[k] = pair_hi[k] = FX_ZERO;
  pair_bin = NO_PAIR;
}

// Adds lo to entry j and hi to entry j + 1 of set s; nothing when !ok (lo and hi must then be
// 0: the private histogram adds them without a branch).
void pair_add_set(uint s, bool ok, uint j, vec4 lo, vec4 hi) {
  const Fx l0 = fx_signed_term(lo.x), l1 = fx_signed_term(lo.y), l2 = fx_signed_term(lo.z), l3 = fx_signed_term(lo.w);
  const Fx h0 = fx_signed_term(hi.x), h1 = fx_signed_term(hi.y), h2 = fx_signed_term(hi.z), h3 = fx_signed_term(hi.w);
  if (MODE == TFM_REDUCE_PRIVATE) {
    // s is a constant at every call: the compiler keeps only its set's adds.
    const uint k = ok ? j : 0u;
#define TFM_PAIR_ADD_SET(s_)                                                                     \
    if (s == uint(s_) && uint(s_) < TFM_PAIR_SETS) {                                            \
      fx_sum(pair_hist##s_##_0[k], l0), fx_sum(pair_hist##s_##_1[k], l1);                       \
      fx_sum(pair_hist##s_##_2[k], l2), fx_sum(pair_hist##s_##_3[k], l3);                       \
      fx_sum(pair_hist##s_##_0[k + 1u], h0), fx_sum(pair_hist##s_##_1[k + 1u], h1);            \
      fx_sum(pair_hist##s_##_2[k + 1u], h2), fx_sum(pair_hist##s_##_3[k + 1u], h3);            \
    }
    TFM_PAIR_ADD_SET(0) TFM_PAIR_ADD_SET(1) TFM_PAIR_ADD_SET(2)
  } else if (ok) {
    // Set 0 comes first for every voxel and starts its run, so the flush is compiled in once per
    // voxel, not once per set (lavapipe: irls_assemble with a flush per set took 4-15 s to compile).
    if (s == 0u && j != pair_bin) {
      pair_flush_run();
      pair_bin = j;
    }
    const uint r = 4u * s;
    fx_sum(pair_lo[r + 0u], l0), fx_sum(pair_lo[r + 1u], l1), fx_sum(pair_lo[r + 2u], l2), fx_sum(pair_lo[r + 3u], l3);
    fx_sum(pair_hi[r + 0u], h0), fx_sum(pair_hi[r + 1u], h1), fx_sum(pair_hi[r + 2u], h2), fx_sum(pair_hi[r + 3u], h3);
  }
}

void pair_add(bool ok, uint j, vec4 lo, vec4 hi) { pair_add_set(0u, ok, j, lo, hi); }

// Adds what the invocation holds to the slots of entries 0..n-1 of every set.
void pair_end(uint n) {
  if (MODE == TFM_REDUCE_PRIVATE) {
    for (uint j = 0u; j < n; ++j) {
#define TFM_PAIR_FLUSH(s, c) \
      if (uint(s) < TFM_PAIR_SETS) TFM_ADD_GLOBAL(uint(s) * TFM_PAIR_SET_STRIDE + 4u * j + uint(c), pair_hist##s##_##c[j])
      TFM_PAIR_EACH(TFM_PAIR_FLUSH)
    }
  } else {
    pair_flush_run();
  }
}

#endif
