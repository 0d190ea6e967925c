// Pipelines, dispatch and decoding of the IRLS pass (irls_assemble).
#include "tfmatch/kernels/irls.h"

#include <stdexcept>
#include <string>

#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/shaders/solver_layout.h"

namespace tfm {

uint64_t irls_state_bytes(uint32_t tf_size) { return (uint64_t(tf_size) + 1) * 16; }

uint64_t irls_accumulator_bytes(uint32_t tf_size) { return uint64_t(TFM_IRLS_ACCUM_WORDS(tf_size)) * sizeof(uint32_t); }

IrlsSums IrlsSums::from_words(uint32_t n, const std::vector<uint32_t>& words) {
  if (n < 2 || words.size() != irls_accumulator_bytes(n) / 4)
    throw std::invalid_argument("IrlsSums: " + std::to_string(words.size()) + " words do not hold the sums of " +
                                std::to_string(n) + " entries");
  const auto loss_words = words.begin() + TFM_FIXED_SLOT_WORDS * TFM_IRLS_LOSS_SLOT(n);
  const std::vector<double> sets = decode_signed_fixed_point(std::vector<uint32_t>(words.begin(), loss_words));
  const std::vector<double> loss = decode_fixed_point(std::vector<uint32_t>(loss_words, words.end()));
  IrlsSums s;
  s.n = n;
  for (uint32_t c = 0; c < 4; ++c) {
    s.diag[c].resize(n);
    s.off[c].resize(n - 1);
    s.rhs[c].resize(n);
    for (uint32_t j = 0; j < n; ++j) {
      s.diag[c][j] = sets[TFM_IRLS_SET_SLOT(TFM_IRLS_SET_DIAG, j, c, n)];
      s.rhs[c][j] = sets[TFM_IRLS_SET_SLOT(TFM_IRLS_SET_RHS, j, c, n)];
      if (j + 1 < n) s.off[c][j] = sets[TFM_IRLS_SET_SLOT(TFM_IRLS_SET_OFF, j, c, n)];
    }
    s.l1[c] = loss[c];
  }
  return s;
}

IrlsKernel::IrlsKernel(Context& ctx, uint32_t tf_size, ReductionOptions options)
    // Three sums per entry and channel: the private path holds as many 64-bit sums per lane as
    // the assembly's (kPrivateHistogramSlots), 12 an entry, so up to 938 entries (the gradient's
    // 4 an entry reach 1024).
    : pass_(ctx, tf_size,
            {"irls_assemble", TFM_IRLS_LOSS_SLOT(tf_size), kPrivateHistogramSlots / (4 * TFM_IRLS_SETS), {}},
            options) {}

void IrlsKernel::record(CommandBatch& batch, const DeviceField& ref, const DeviceField& opt,
                        const FieldMapping& ref_map, const FieldMapping& opt_map, const Buffer& ref_tf,
                        const Buffer& state, Buffer& accum) const {
  const uint32_t n = pass_.tf_size();
  if (accum.size() < irls_accumulator_bytes(n) || state.size() < irls_state_bytes(n))
    throw std::invalid_argument("irls_assemble: accumulator or state buffer too small");
  pass_.record(batch, ref, opt, ref_map, opt_map, ref_tf, state, accum);
}

}  // namespace tfm
