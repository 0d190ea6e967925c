// The assembly's read bound (kernels/read_bound.h) against its CPU reference: sizes around a quad,
// a workgroup and a segment, fields split into chunks of 1024 voxels and dispatches of 64 quads
// (ranges that start inside a chunk), NaN and infinities among the values; a voxel left out or
// read twice changes the sums.
#include <array>
#include <bit>
#include <cmath>
#include <random>
#include <vector>

#include "read_bound.h"
#include "shared_layout.h"
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

TEST_F(ReadBound, SumsEveryValueOnceOnAwkwardSizesChunksAndRanges) {
  const size_t segment_quads = size_t(ctx().subgroup_size()) * TFM_REDUCE_SEGMENT_STEPS;
  for (size_t n : {size_t(1), size_t(3), size_t(4), size_t(5), size_t(TFM_VOXEL_WORKGROUP * 4 + 3),
                   4 * segment_quads + 1, size_t(70001)}) {
    const std::vector<float> ref = values(n, uint32_t(n)), opt = values(n, uint32_t(n + 7));
    const std::array<uint32_t, 2> expected = sums_of_bits(ref, opt);
    EXPECT_EQ(field_pair_bit_sums(ref, opt), expected) << n << " voxels";
    for (uint64_t chunk : {uint64_t(0), uint64_t(1024)}) {
      for (uint64_t range_quads : {uint64_t(0), uint64_t(64)}) {
        SCOPED_TRACE(testing::Message() << n << " voxels, chunks " << chunk << ", range " << range_quads);
        const DeviceField dref(ctx(), ref, "ref", chunk), dopt(ctx(), opt, "opt", chunk);
        const FieldPairReadKernel kernel(ctx(), range_quads);
        double ms = 0.0;
        EXPECT_EQ(kernel.run(dref, dopt, &ms), expected);
        // The GPU time where the device has timestamps, else -1 (read_bound.h).
        if (ctx().timestamps_supported())
          EXPECT_GE(ms, 0.0);
        else
          EXPECT_EQ(ms, -1.0);
      }
    }
  }
}

TEST_F(ReadBound, ReferenceSeesAVoxelLeftOutOrReadTwice) {
  const std::vector<float> v = values(1001, 3);
  const std::array<uint32_t, 2> all = field_pair_bit_sums(v, v);
  std::vector<float> missing(v.begin(), v.end() - 1), twice = v;
  twice.push_back(v[500]);
  EXPECT_NE(field_pair_bit_sums(missing, v), all);
  EXPECT_NE(field_pair_bit_sums(v, twice), all);
  EXPECT_THROW(FieldPairReadKernel(ctx(), 100), std::invalid_argument);
}

}  // namespace
}  // namespace tfm
