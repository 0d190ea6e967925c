// Histograms of device fields (shaders/field_histogram.comp): B equal bins over a value range,
// with counts below, above and NaN, summed in 64 bits on the host. The histogram-matching solver
// builds both fields' quantile functions from these; the exact counts make the result the same on
// every device, run and chunking.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/engine/pipeline.h"
#include "tfmatch/model/field_histogram.h"  // FieldHistogram, the bin arithmetic

namespace tfm {

class Context;

// Where the shader keeps its counts (field_histogram.comp): Auto takes Private on CPU devices
// within kPrivateHistogramCounters, else Shared where the counters fit the workgroup's shared
// memory, else Global.
enum class HistogramMode { Auto, Private, Shared, Global };
// Counters one invocation keeps privately on a CPU device (private_limit() on others): those of
// 4096 bins, histogram-matching's default. The private array is one array, and lavapipe's compile
// time grows with its size (docs/benchmarks.md, "A cold shader cache"); measured with the cache
// empty, 20 M voxels: 4096 bins private 9.0 s to compile, 48 ms a run; 8192 bins private 16.5 s
// and 50 ms, against 0.3 s and ~185 ms in shared memory, which takes the larger histograms.
inline constexpr uint32_t kPrivateHistogramCounters = TFM_HIST_COUNTERS(4096u);

class FieldHistogramKernel {
 public:
  // `bins` in [1, TFM_HIST_MAX_BINS] (std::invalid_argument otherwise). `mode` forces a path
  // (tests; std::invalid_argument where the device cannot hold its counters).
  FieldHistogramKernel(Context& ctx, uint32_t bins, HistogramMode mode = HistogramMode::Auto);
  uint32_t bins() const { return bins_; }
  HistogramMode mode() const { return mode_; }
  // The histogram of `field` over [lo, hi] (finite, lo < hi; std::invalid_argument otherwise).
  FieldHistogram run(const DeviceField& field, double lo, double hi) const;

 private:
  Context& ctx_;
  uint32_t bins_;
  HistogramMode mode_;
  uint32_t workgroup_size_;
  uint64_t lane_voxels_;  // Private: voxels per lane, so that a lane's flush is small beside them
  SharedPipeline pipeline_;
};

}  // namespace tfm
