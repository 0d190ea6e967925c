// What the benchmarks share for timing: wall seconds since a point, and the best device time of
// a warm run.
#pragma once

#include <algorithm>
#include <chrono>

namespace tfm::cli {

double seconds_since(std::chrono::steady_clock::time_point t0);

// Best device time (ms) of `run` (which returns its own GPU time) over at least `repeats` runs and
// `warm_ms` of back-to-back device work. A GPU left idle (through a CPU loop between repeats, or
// before the first) drops its clocks: an H100 or H200 idles at 345 MHz, 5.7x below its 1980 MHz
// boost. Timed without warming on an H200 (2026-11-27), the assembly took 15.9 ms in `bench` and
// 2.8 ms inside `optimize`, where uploads had just kept the GPU busy: 5.7x, the clocks' ratio. So
// each round keeps the device busy for a while before its best time counts.
template <class Run>
double warm_best_ms(int repeats, Run&& run, int warm_ms = 200) {
  double best = 1e300;
  const auto warm_until = std::chrono::steady_clock::now() + std::chrono::milliseconds(warm_ms);
  for (int r = 0; r < repeats || std::chrono::steady_clock::now() < warm_until; ++r) best = std::min(best, run());
  return best;
}

}  // namespace tfm::cli
