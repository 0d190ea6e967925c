// CPU reference of the field histogram.
#include "tfmatch/reference/histogram_cpu.h"

#include <stdexcept>
#include <vector>

namespace tfm {

FieldHistogram field_histogram_cpu(std::span<const float> values, double lo, double hi, uint32_t bins) {
  if (bins < 1 || !(lo < hi)) throw std::invalid_argument("field_histogram_cpu: bad bins or range");
  std::vector<uint64_t> counters(TFM_HIST_COUNTERS(bins), 0);
  const float flo = float(lo), scale = histogram_scale(lo, hi, bins);
  for (float v : values) ++counters[histogram_counter(v, flo, scale, bins)];
  FieldHistogram h;
  h.lo = lo;
  h.hi = hi;
  h.below = counters[TFM_HIST_BELOW];
  h.above = counters[TFM_HIST_ABOVE(bins)];
  h.nan = counters[TFM_HIST_NAN(bins)];
  h.bins.assign(counters.begin() + 1, counters.begin() + 1 + bins);
  return h;
}

}  // namespace tfm
