// The synthetic ensemble has the dependence structure its header promises (checked with the
// double-precision CPU references) and is the same on every call.
#include <gtest/gtest.h>

#include <cmath>

#include "tfmatch/model/synthetic_ensemble.h"
#include "tfmatch/reference/correlation_cpu.h"

namespace tfm {
namespace {

std::vector<double> series_at(const Ensemble& e, const std::array<double, 3>& c) {
  const auto& d = e.grid.dims;
  const uint64_t v = (uint64_t(std::lround(c[2])) * d[1] + uint64_t(std::lround(c[1]))) * d[0] + uint64_t(std::lround(c[0]));
  const std::vector<float> s = ensemble_series(e.view(), v);
  return {s.begin(), s.end()};
}

TEST(SyntheticEnsemble, DependenceIsWhereTheBlobsSayAndDeterministic) {
  const Ensemble e = synthetic_ensemble(24, 24, 12, 200, 3);
  ASSERT_EQ(e.member_count, 200u);
  const EnsembleBlobs b = synthetic_ensemble_blobs(24, 24, 12);
  const GridIndex p = synthetic_ensemble_reference(e);
  const std::vector<double> ref = series_at(e, {double(p[0]), double(p[1]), double(p[2])});
  const auto a = series_at(e, b.centre[0]), n = series_at(e, b.centre[1]), q = series_at(e, b.centre[2]),
             c = series_at(e, b.centre[3]);
  EXPECT_GT(pearson_cpu(ref, a), 0.95);
  EXPECT_LT(pearson_cpu(ref, n), -0.7);
  EXPECT_LT(std::abs(pearson_cpu(ref, q)), 0.3);   // non-monotone: Pearson does not see it
  EXPECT_LT(std::abs(pearson_cpu(ref, c)), 0.3);   // independent
  EXPECT_GT(mutual_information_kraskov_cpu(ref, q, 3), 0.25);  // mutual information does
  EXPECT_LT(mutual_information_kraskov_cpu(ref, c, 3), 0.15);
  const Ensemble again = synthetic_ensemble(24, 24, 12, 200, 3);
  EXPECT_EQ(again.values, e.values);
  EXPECT_NE(synthetic_ensemble(24, 24, 12, 200, 4).values, e.values);
}

// A part of the grid is the whole ensemble's values there, bit for bit, member-major; a range
// past the grid ends with it.
TEST(SyntheticEnsemble, AnyRangeOfVoxelsIsTheWholeEnsemblesValues) {
  const Ensemble e = synthetic_ensemble(13, 7, 5, 9, 2);
  const uint64_t n = e.voxel_count();
  for (const auto& [begin, end] : std::vector<std::pair<uint64_t, uint64_t>>{{0, n}, {91, 92}, {57, 301}, {400, n + 50}}) {
    const std::vector<float> part = synthetic_ensemble_voxels(13, 7, 5, 9, begin, end, 2);
    const uint64_t count = std::min(end, n) - begin;
    ASSERT_EQ(part.size(), 9 * count) << begin << ".." << end;
    for (uint32_t m = 0; m < 9; ++m)
      for (uint64_t i = 0; i < count; ++i)
        ASSERT_EQ(part[m * count + i], e.values[m * n + begin + i]) << "member " << m << ", voxel " << begin + i;
  }
}

}  // namespace
}  // namespace tfm
