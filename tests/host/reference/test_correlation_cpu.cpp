// The double-precision references and the multi-threaded CPU implementation of the correlation
// measures (host/reference/correlation_cpu.h): values computed independently by scipy and
// scikit-learn (tests/host/reference/correlation_expected.py), closed forms, the NaN and
// constant-series conventions, input errors, and the fast CPU methods against the references.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <random>
#include <stdexcept>

#include <gtest/gtest.h>

#include "correlation_expected.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/reference/correlation_cpu.h"
#include "tfmatch/selftest/selftest_support.h"

namespace tfm {
namespace {

std::vector<double> as_double(const std::vector<float>& v) { return {v.begin(), v.end()}; }

TEST(CorrelationReference, MatchesScipyAndScikitLearn) {
  for (const test::ExpectedCorrelations& ex : test::expected_correlations()) {
    SCOPED_TRACE(ex.name);
    const std::vector<double> x = as_double(ex.x), y = as_double(ex.y);
    // Same definitions in double: only rounding differs.
    EXPECT_NEAR(pearson_cpu(x, y), ex.pearson, 1e-12);
    EXPECT_NEAR(spearman_cpu(x, y), ex.spearman, 1e-12);
    EXPECT_NEAR(kendall_tau_b_cpu(x, y), ex.kendall, 1e-12);
    EXPECT_NEAR(mutual_information_kraskov_cpu(x, y, 1), ex.ksg_k1, 1e-12);
    EXPECT_NEAR(mutual_information_kraskov_cpu(x, y, 3), ex.ksg_k3, 1e-12);
    EXPECT_NEAR(mutual_information_binned_cpu(x, y, 4), ex.binned_4, 1e-12);
    EXPECT_NEAR(mutual_information_binned_cpu(x, y, 8), ex.binned_8, 1e-12);
  }
}

// The fast CPU methods (float results) on the same series.
TEST(CorrelationFieldCpu, MatchesScipyAndScikitLearn) {
  for (const test::ExpectedCorrelations& ex : test::expected_correlations()) {
    SCOPED_TRACE(ex.name);
    const EnsembleView view{ex.y.data(), uint32_t(ex.y.size()), 1};
    auto run = [&](CorrelationParams p) { return double(correlation_field_cpu(view, ex.x, p)[0]); };
    EXPECT_NEAR(run({CorrelationMeasure::Pearson}), ex.pearson, 1e-6);
    EXPECT_NEAR(run({CorrelationMeasure::Spearman}), ex.spearman, 1e-6);
    EXPECT_NEAR(run({CorrelationMeasure::Kendall}), ex.kendall, 1e-6);
    EXPECT_NEAR(run({CorrelationMeasure::MiKraskov, 16, 1}), ex.ksg_k1, 1e-6);
    EXPECT_NEAR(run({CorrelationMeasure::MiKraskov, 16, 3}), ex.ksg_k3, 1e-6);
    EXPECT_NEAR(run({CorrelationMeasure::MiBinned, 4}), ex.binned_4, 1e-6);
    EXPECT_NEAR(run({CorrelationMeasure::MiBinned, 8}), ex.binned_8, 1e-6);
  }
}

// Closed forms: a strictly monotone transform keeps every pair's order (rank measures exactly 1,
// -1 reversed); a linear one gives Pearson 1.
TEST(CorrelationReference, MonotoneTransformsGiveOne) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-2, 2);
  std::vector<double> x(50), up(50), down(50), linear(50);
  for (size_t i = 0; i < x.size(); ++i) {
    x[i] = u(rng);
    up[i] = std::exp(3 * x[i]) + x[i];
    down[i] = -x[i] * x[i] * x[i];
    linear[i] = 2.5 * x[i] - 1;
  }
  EXPECT_EQ(spearman_cpu(x, up), 1.0);
  EXPECT_EQ(kendall_tau_b_cpu(x, up), 1.0);
  EXPECT_EQ(spearman_cpu(x, down), -1.0);
  EXPECT_EQ(kendall_tau_b_cpu(x, down), -1.0);
  EXPECT_NEAR(pearson_cpu(x, linear), 1.0, 1e-14);
  EXPECT_LT(pearson_cpu(x, up), 0.99);  // not linear
}

// Kendall's tau-b with every tie term, counted by hand: x = 1 1 2 3, y = 1 2 2 2. Pairs: (1,2)
// tied in x, (2,3) (2,4) (3,4) tied in y, (1,3) (1,4) concordant: n0 = 6, n1 = 1, n2 = 3,
// tau_b = 2 / sqrt(5 * 3).
TEST(CorrelationReference, KendallTieTermsByHand) {
  const std::vector<double> x{1, 1, 2, 3}, y{1, 2, 2, 2};
  EXPECT_NEAR(kendall_tau_b_cpu(x, y), 2 / std::sqrt(15.0), 1e-15);
}

TEST(CorrelationReference, NanAndConstantSeriesFollowTheConventions) {
  const std::vector<double> x{1, 2, 3, 4}, c{2, 2, 2, 2}, n{1, NAN, 3, 4};
  for (const CorrelationParams& p : {CorrelationParams{CorrelationMeasure::Pearson}, {CorrelationMeasure::Spearman},
                                     {CorrelationMeasure::Kendall}}) {
    EXPECT_TRUE(std::isnan(correlation_cpu(x, c, p)));
    EXPECT_TRUE(std::isnan(correlation_cpu(c, x, p)));
    EXPECT_TRUE(std::isnan(correlation_cpu(x, n, p)));
  }
  for (const CorrelationParams& p : {CorrelationParams{CorrelationMeasure::MiBinned, 4},
                                     {CorrelationMeasure::MiKraskov, 16, 2}, {CorrelationMeasure::MiCoefficient, 16, 2}}) {
    EXPECT_EQ(correlation_cpu(x, c, p), 0.0);
    EXPECT_EQ(correlation_cpu(c, x, p), 0.0);
    EXPECT_TRUE(std::isnan(correlation_cpu(n, x, p)));
    EXPECT_TRUE(std::isnan(correlation_cpu(c, n, p)));  // NaN wins over constant
  }
}

TEST(CorrelationReference, RejectsBadInput) {
  const std::vector<double> two{1, 2}, three{1, 2, 3}, four{1, 2, 3, 4};
  EXPECT_THROW(pearson_cpu(two, two), std::invalid_argument);
  EXPECT_THROW(kendall_tau_b_cpu(three, four), std::invalid_argument);
  EXPECT_THROW(correlation_cpu(four, four, {CorrelationMeasure::MiBinned, 1}), std::invalid_argument);
  EXPECT_THROW(correlation_cpu(four, four, {CorrelationMeasure::MiKraskov, 16, 4}), std::invalid_argument);
  EXPECT_THROW(correlation_cpu(four, four, {CorrelationMeasure::MiKraskov, 16, 0}), std::invalid_argument);
  EXPECT_THROW(parse_correlation_measure("pearsn"), std::invalid_argument);
  EXPECT_EQ(parse_correlation_measure("mi-kraskov"), CorrelationMeasure::MiKraskov);
  for (const std::string& name : correlation_measure_names())
    EXPECT_STREQ(correlation_measure_name(parse_correlation_measure(name)), name.c_str());
}

// The fast methods (O(M log M) Kendall, sort-and-search Spearman, band-search Kraskov) on all
// cores against the definitions, with the kernels' bound (the test ensemble makes every
// comparison exact in float), and the same bits for 1 and 3 threads.
TEST(CorrelationFieldCpu, MatchesTheReferencesWhateverTheThreads) {
  const CorrelationParams measures[] = {
      {CorrelationMeasure::Pearson},          {CorrelationMeasure::Spearman},          {CorrelationMeasure::Kendall},
      {CorrelationMeasure::MiBinned, 8},      {CorrelationMeasure::MiKraskov, 16, 3},  {CorrelationMeasure::MiCoefficient, 16, 4}};
  for (CorrelationParams p : measures)
    for (uint32_t members : {3u, 4u, 33u, 200u}) {
      p.k = std::min(p.k, members - 1);  // k < M
      SCOPED_TRACE(std::string(correlation_measure_name(p.measure)) + ", M = " + std::to_string(members));
      const selftest::CorrelationEnsemble e = selftest::correlation_test_ensemble(members, 150, members);
      const std::vector<float> reference = e.reference();
      const std::vector<float> one = correlation_field_cpu(e.view(), reference, p, 1);
      const std::vector<float> three = correlation_field_cpu(e.view(), reference, p, 3);
      EXPECT_EQ(std::memcmp(one.data(), three.data(), one.size() * sizeof(float)), 0);
      const std::vector<double> r = correlation_field_reference(e.view(), reference, p);
      const double bound = CorrelationKernel::error_bound(p, members);
      for (size_t v = 0; v < r.size(); ++v) {
        if (std::isnan(r[v])) ASSERT_TRUE(std::isnan(one[v])) << "voxel " << v;
        else ASSERT_NEAR(one[v], r[v], bound) << "voxel " << v;
      }
    }
}

}  // namespace
}  // namespace tfm
