// Field-histogram kernel beyond its case table (host/selftest/selftest_voxel.cpp, run by
// test_kernel_cases.cpp: awkward sizes, NaN, values outside and on the range's ends, every path,
// 1 to 65536 bins, against field_histogram_cpu): the same counts whatever the chunking, private
// counts over long lanes, bad bins and ranges, and the reference's binning against an independent
// double-precision computation away from bin edges.
#include <cmath>
#include <random>
#include <vector>

#include "tfmatch/kernels/histogram.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/reference/histogram_cpu.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

std::vector<float> awkward_values(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-3.0f, 13.0f);  // range below is [0, 10]: some outside
  std::vector<float> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = i % 17 == 5 ? NAN : (i % 23 == 7 ? 10.0f : (i % 29 == 3 ? 0.0f : u(rng)));
  return v;
}

void expect_equal(const FieldHistogram& gpu, const FieldHistogram& cpu) {
  EXPECT_EQ(gpu.below, cpu.below);
  EXPECT_EQ(gpu.above, cpu.above);
  EXPECT_EQ(gpu.nan, cpu.nan);
  ASSERT_EQ(gpu.bins.size(), cpu.bins.size());
  for (size_t k = 0; k < gpu.bins.size(); ++k) ASSERT_EQ(gpu.bins[k], cpu.bins[k]) << "bin " << k;
}

class Histogram : public test::GpuTest {};

TEST_F(Histogram, SameCountsWhateverTheChunkingAndBeyondSharedMemory) {
  const std::vector<float> values = awkward_values(50000, 3);
  const FieldHistogram cpu = field_histogram_cpu(values, -1.0, 11.0, 65536);
  for (uint64_t chunk : {uint64_t(0), uint64_t(4096), uint64_t(12345)}) {
    SCOPED_TRACE(chunk);
    DeviceField field(ctx(), values, "chunked field", chunk);
    FieldHistogramKernel kernel(ctx(), 65536);  // 65539 counters: beyond shared memory and the private budget
    EXPECT_EQ(kernel.mode(), HistogramMode::Global);
    expect_equal(kernel.run(field, -1.0, 11.0), cpu);
  }
  EXPECT_THROW(FieldHistogramKernel(ctx(), 65536, HistogramMode::Private), std::invalid_argument);
  EXPECT_THROW(FieldHistogramKernel(ctx(), 65536, HistogramMode::Shared), std::invalid_argument);
}

// Lanes on quads in ranges: the private path over enough voxels for long lanes, a tail of 3, and
// chunks, each against the reference; Auto takes the private path on a CPU device.
TEST_F(Histogram, PrivateCountsOverLongLanesAndChunks) {
  const std::vector<float> values = awkward_values(1000003, 5);
  const FieldHistogram cpu = field_histogram_cpu(values, 0.0, 10.0, 1000);
  const FieldHistogramKernel automatic(ctx(), 1000);
  if (ctx().properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU) EXPECT_EQ(automatic.mode(), HistogramMode::Private);
  for (uint64_t chunk : {uint64_t(0), uint64_t(262144 + 4)}) {
    SCOPED_TRACE(chunk);
    DeviceField field(ctx(), values, "long field", chunk);
    expect_equal(FieldHistogramKernel(ctx(), 1000, HistogramMode::Private).run(field, 0.0, 10.0), cpu);
    expect_equal(automatic.run(field, 0.0, 10.0), cpu);
  }
}

// Auto keeps private counters up to histogram-matching's 4096 bins on a CPU device; a larger
// histogram goes to shared memory, which compiles in a fraction of the time (kernels/histogram.h).
TEST_F(Histogram, PrivateCountersUpTo4096BinsOnACpuDevice) {
  if (ctx().properties().deviceType != VK_PHYSICAL_DEVICE_TYPE_CPU)
    GTEST_SKIP() << ctx().device_name() << ": private counters are for CPU devices";
  EXPECT_EQ(FieldHistogramKernel(ctx(), 4096).mode(), HistogramMode::Private);
  EXPECT_THROW(FieldHistogramKernel(ctx(), 4097, HistogramMode::Private), std::invalid_argument);
  const bool fits_shared = TFM_HIST_COUNTERS(4097u) * sizeof(uint32_t) <= ctx().limits().maxComputeSharedMemorySize;
  EXPECT_EQ(FieldHistogramKernel(ctx(), 4097).mode(), fits_shared ? HistogramMode::Shared : HistogramMode::Global);
}

TEST_F(Histogram, RejectsBadBinsAndRanges) {
  EXPECT_THROW(FieldHistogramKernel(ctx(), 0), std::invalid_argument);
  EXPECT_THROW(FieldHistogramKernel(ctx(), TFM_HIST_MAX_BINS + 1), std::invalid_argument);
  FieldHistogramKernel kernel(ctx(), 16);
  DeviceField field(ctx(), std::vector<float>{1.0f, 2.0f}, "two voxels");
  EXPECT_THROW(kernel.run(field, 1.0, 1.0), std::invalid_argument);
  EXPECT_THROW(kernel.run(field, 0.0, INFINITY), std::invalid_argument);
  EXPECT_THROW(kernel.run(field, 0.0, 1e-45), std::invalid_argument);  // scale overflows float
}

// The float32 binning is what double arithmetic gives, except for values within rounding of an
// edge (where either bin is right).
TEST(HistogramReference, BinsAsDoubleArithmeticAwayFromEdges) {
  const std::vector<float> values = awkward_values(20000, 9);
  const double lo = 0.0, hi = 10.0;
  const uint32_t bins = 333;
  const FieldHistogram h = field_histogram_cpu(values, lo, hi, bins);
  std::vector<uint64_t> expect(bins, 0);
  uint64_t below = 0, above = 0, nan = 0, near_edge = 0;
  for (float v : values) {
    if (std::isnan(v)) { ++nan; continue; }
    if (v < lo) { ++below; continue; }
    if (v > hi) { ++above; continue; }
    const double t = (double(v) - lo) / (hi - lo) * bins;
    if (std::abs(t - std::round(t)) < 1e-4 && t > 0.5 && t < bins - 0.5) ++near_edge;
    ++expect[std::min<uint64_t>(uint64_t(t), bins - 1)];
  }
  EXPECT_EQ(h.below, below);
  EXPECT_EQ(h.above, above);
  EXPECT_EQ(h.nan, nan);
  uint64_t differ = 0;
  for (uint32_t k = 0; k < bins; ++k) differ += uint64_t(std::llabs(int64_t(h.bins[k]) - int64_t(expect[k])));
  EXPECT_LE(differ, 2 * near_edge);
  EXPECT_EQ(h.bins[bins - 1] >= uint64_t(std::count(values.begin(), values.end(), 10.0f)), true);
}

}  // namespace
}  // namespace tfm
