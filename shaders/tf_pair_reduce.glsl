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
#ifndef TFMATCH_TF_PAIR_REDUCE_GLSL
#define TFMATCH_TF_PAIR_REDUCE_GLSL

Fx pair_hist[4u * PRIVATE_BINS + 1u];
Fx pair_lo[4], pair_hi[4];   // run sums of entries pair_bin, pair_bin + 1
uint pair_bin;               // NO_PAIR between runs
const uint NO_PAIR = 0xFFFFFFFFu;

void pair_slot_add(uint k, Fx v) {
  if (MODE == TFM_REDUCE_RUNS_SHARED) TFM_ADD_SHARED(k, v)
  else TFM_ADD_GLOBAL(k, v)
}

void pair_flush_run() {
  if (pair_bin == NO_PAIR) return;
  for (uint c = 0u; c < 4u; ++c) {
    pair_slot_add(4u * pair_bin + c, pair_lo[c]);
    pair_slot_add(4u * (pair_bin + 1u) + c, pair_hi[c]);
    pair_lo[c] = pair_hi[c] = FX_ZERO;
  }
}

void pair_begin() {
  for (uint j = 0u; j < PRIVATE_BINS; ++j)
    for (uint c = 0u; c < 4u; ++c) pair_hist[4u * j + c] = FX_ZERO;
  for (uint c = 0u; c < 4u; ++c) pair_lo[c] = pair_hi[c] = FX_ZERO;
  pair_bin = NO_PAIR;
}

// Adds lo to entry j and hi to entry j + 1; nothing when !ok (lo and hi must then be 0: the
// private histogram adds them without a branch).
void pair_add(bool ok, uint j, vec4 lo, vec4 hi) {
  const Fx l0 = fx_signed_term(lo.x), l1 = fx_signed_term(lo.y), l2 = fx_signed_term(lo.z), l3 = fx_signed_term(lo.w);
  const Fx h0 = fx_signed_term(hi.x), h1 = fx_signed_term(hi.y), h2 = fx_signed_term(hi.z), h3 = fx_signed_term(hi.w);
  if (MODE == TFM_REDUCE_PRIVATE) {
    const uint base = 4u * (ok ? j : 0u);
    fx_sum(pair_hist[base + 0u], l0), fx_sum(pair_hist[base + 1u], l1);
    fx_sum(pair_hist[base + 2u], l2), fx_sum(pair_hist[base + 3u], l3);
    fx_sum(pair_hist[base + 4u], h0), fx_sum(pair_hist[base + 5u], h1);
    fx_sum(pair_hist[base + 6u], h2), fx_sum(pair_hist[base + 7u], h3);
  } else if (ok) {
    if (j != pair_bin) {
      pair_flush_run();
      pair_bin = j;
    }
    fx_sum(pair_lo[0], l0), fx_sum(pair_lo[1], l1), fx_sum(pair_lo[2], l2), fx_sum(pair_lo[3], l3);
    fx_sum(pair_hi[0], h0), fx_sum(pair_hi[1], h1), fx_sum(pair_hi[2], h2), fx_sum(pair_hi[3], h3);
  }
}

// Adds what the invocation holds to the slots of entries 0..n-1.
void pair_end(uint n) {
  if (MODE == TFM_REDUCE_PRIVATE) {
    for (uint j = 0u; j < n; ++j)
      for (uint c = 0u; c < 4u; ++c) TFM_ADD_GLOBAL(4u * j + c, pair_hist[4u * j + c])
  } else {
    pair_flush_run();
  }
}

#endif
