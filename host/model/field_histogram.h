// A histogram as data: B equal bins over a value range, with counts below, above and NaN, in 64
// bits, and the float32 bin arithmetic the GPU kernel (kernels/histogram.h) and the CPU reference
// (host/reference/histogram_cpu.h) share bit for bit. GPU-free.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "tfmatch/model/field_mapping.h"  // no_data
#include "tfmatch/shaders/histogram_layout.h"

namespace tfm {

struct FieldHistogram {
  double lo = 0.0, hi = 1.0;    // the range the bins divide
  std::vector<uint64_t> bins;   // B counts; bin k holds [lo + k w, lo + (k+1) w), the last also hi
  uint64_t below = 0, above = 0, nan = 0;  // nan: values without data (NaN, ±Inf)
  uint64_t finite() const;      // below + above + all bins
};

// The float32 bin arithmetic of the shader (bit-identical on the host): the scale it uses for
// [lo, hi] and the counter (histogram_layout.h) a value goes to.
inline float histogram_scale(double lo, double hi, uint32_t bins) { return float(double(bins) / (hi - lo)); }
inline uint32_t histogram_counter(float v, float lo, float scale, uint32_t bins) {
  if (no_data(v)) return TFM_HIST_NAN(bins);
  volatile float t = (v - lo) * scale;  // volatile: no contraction or excess precision, as `precise`
  if (t < 0.0f) return TFM_HIST_BELOW;
  if (t > float(bins)) return TFM_HIST_ABOVE(bins);
  return 1u + std::min(uint32_t(std::floor(t)), bins - 1u);
}

}  // namespace tfm
