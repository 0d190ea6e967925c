// The assembly's read bound (kernels/read_bound.h) beyond its case table (host/selftest/
// selftest_voxel.cpp, run by test_kernel_cases.cpp: sizes around a quad, a workgroup and a
// segment, chunks of 1024 voxels, dispatches of 64 quads, NaN and infinities): its GPU time, and
// a reference that notices a voxel left out or read twice.
#include <array>
#include <bit>
#include <cmath>
#include <random>
#include <vector>

#include "tfmatch/kernels/read_bound.h"
#include "tfmatch/shaders/shared_layout.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

std::vector<float> values(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-5.0f, 5.0f);
  std::vector<float> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = i % 19 == 4 ? NAN : (i % 31 == 9 ? INFINITY : u(rng));
  return v;
}

class ReadBound : public test::GpuTest {};

// The sums the kernel must return, computed here (field_pair_bit_sums is the library's own):
// every value's bit pattern once, modulo 2^32.
std::array<uint32_t, 2> sums_of_bits(const std::vector<float>& ref, const std::vector<float>& opt) {
  uint64_t a = 0, b = 0;
  for (float v : ref) a += std::bit_cast<uint32_t>(v);
  for (float v : opt) b += std::bit_cast<uint32_t>(v);
  return {uint32_t(a & 0xffffffffu), uint32_t(b & 0xffffffffu)};
}

// The GPU time where the device has timestamps, else -1 (read_bound.h).
TEST_F(ReadBound, ReportsTheGpuTimeWhereTheDeviceHasTimestamps) {
  const std::vector<float> ref = values(70001, 1), opt = values(70001, 2);
  const DeviceField dref(ctx(), ref, "ref", 1024), dopt(ctx(), opt, "opt", 1024);
  double ms = -2.0;  // neither a time nor the -1 of no timestamps: run() must write it
  EXPECT_EQ(FieldPairReadKernel(ctx(), 64).run(dref, dopt, &ms), sums_of_bits(ref, opt));
  if (ctx().timestamps_supported())
    EXPECT_TRUE(std::isfinite(ms) && ms >= 0.0) << ms;
  else
    EXPECT_EQ(ms, -1.0);
}

// Every lane length (the workgroup count: quad_segments.glsl spreads a dispatch over all its
// lanes) reads every voxel once: lanes of one quad, of a few segments, longer than the range, over
// one dispatch and over chunks and ranges that split it.
TEST_F(ReadBound, EveryLaneLengthReadsEveryVoxelOnce) {
  const std::vector<float> ref = values(70001, 4), opt = values(70001, 5);
  const std::array<uint32_t, 2> expected = sums_of_bits(ref, opt);
  for (uint64_t chunk : {uint64_t(0), uint64_t(9216)}) {
    const DeviceField dref(ctx(), ref, "ref", chunk), dopt(ctx(), opt, "opt", chunk);
    for (uint64_t range_quads : {uint64_t(0), uint64_t(640)})
      for (uint64_t lane : {0u, 4u, 12u, 64u, 1000u, 100000u}) {  // 0: the device's layout
        SCOPED_TRACE("chunk " + std::to_string(chunk) + ", range " + std::to_string(range_quads) + ", lanes of " +
                     std::to_string(lane));
        EXPECT_EQ(FieldPairReadKernel(ctx(), range_quads, lane).run(dref, dopt), expected);
      }
  }
}

// The library's reference (field_pair_bit_sums, which the case table holds the kernel to) against
// the sums computed here, and what it must notice.
TEST_F(ReadBound, ReferenceSeesAVoxelLeftOutOrReadTwice) {
  const std::vector<float> v = values(1001, 3);
  const std::array<uint32_t, 2> all = field_pair_bit_sums(v, v);
  EXPECT_EQ(all, sums_of_bits(v, v));
  std::vector<float> missing(v.begin(), v.end() - 1), twice = v;
  twice.push_back(v[500]);
  EXPECT_NE(field_pair_bit_sums(missing, v), all);
  EXPECT_NE(field_pair_bit_sums(v, twice), all);
  EXPECT_THROW(FieldPairReadKernel(ctx(), 100), std::invalid_argument);
}

}  // namespace
}  // namespace tfm
