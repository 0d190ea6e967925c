// Closed forms of the correlation measures on the GPU kernels: a monotone transform of the
// reference gives Spearman = Kendall = 1 (-1 decreasing); an independent shuffled copy gives
// mutual information near 0; a bivariate Gaussian with correlation rho gives Pearson ~ rho,
// Spearman ~ (6/pi) asin(rho/2), Kendall ~ (2/pi) asin(rho), Kraskov MI ~ -ln(1 - rho^2)/2 and
// its coefficient ~ |rho|, within the sampling error of M = 1000 members.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "correlation.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using CorrelationClosedForms = test::GpuTest;

// A member-major ensemble whose voxel v is series[v].
struct Ensemble {
  uint32_t members;
  std::vector<std::vector<float>> series;
  std::vector<float> values;
  explicit Ensemble(const std::vector<std::vector<float>>& s) : members(uint32_t(s[0].size())), series(s) {
    values.resize(series.size() * members);
    for (size_t v = 0; v < series.size(); ++v)
      for (uint32_t m = 0; m < members; ++m) values[m * series.size() + v] = series[v][m];
  }
  EnsembleView view() const { return {values.data(), members, series.size()}; }
};

TEST_F(CorrelationClosedForms, MonotoneTransformsGiveRankCorrelationOne) {
  CorrelationKernel kernel(ctx());
  for (uint32_t members : {20u, 1000u}) {
    // Distinct values 1/64 apart, shuffled: their transforms stay distinct in float.
    std::vector<float> x(members);
    for (uint32_t m = 0; m < members; ++m) x[m] = (float(m) - float(members) / 2) / 64.0f;
    std::shuffle(x.begin(), x.end(), std::mt19937(members));
    std::vector<std::vector<float>> s(4, std::vector<float>(members));
    for (uint32_t m = 0; m < members; ++m) {
      s[0][m] = std::exp(x[m] / 2);
      s[1][m] = x[m] * x[m] * x[m] + x[m];
      s[2][m] = -std::atan(x[m]) * 10;  // decreasing
      s[3][m] = 1.0f / (x[m] + 100.0f);  // decreasing
    }
    const Ensemble e(s);
    for (CorrelationMeasure m : {CorrelationMeasure::Spearman, CorrelationMeasure::Kendall}) {
      const std::vector<float> g = kernel.compute(e.view(), x, {m});
      const double bound = CorrelationKernel::error_bound({m}, members);
      for (size_t v = 0; v < 4; ++v)
        EXPECT_NEAR(g[v], v < 2 ? 1.0 : -1.0, bound) << correlation_measure_name(m) << ", M = " << members << ", voxel " << v;
    }
  }
}

TEST_F(CorrelationClosedForms, ShuffledCopiesCarryNoInformation) {
  const uint32_t members = 1000, copies = 8;
  std::mt19937 rng(21);
  std::normal_distribution<float> normal;
  std::vector<float> x(members);
  for (float& v : x) v = normal(rng);
  std::vector<std::vector<float>> s(copies, x);
  for (auto& c : s) std::shuffle(c.begin(), c.end(), rng);
  const Ensemble e(s);
  CorrelationKernel kernel(ctx());
  // Kraskov is close to unbiased at 0 (its spread here is ~0.01); the binned plug-in estimate is
  // biased upwards by about (B - 1)^2 / (2M) = 0.0245 for 8 bins.
  const std::vector<float> ksg = kernel.compute(e.view(), x, {CorrelationMeasure::MiKraskov, 16, 3});
  const std::vector<float> binned = kernel.compute(e.view(), x, {CorrelationMeasure::MiBinned, 8});
  double mean = 0;
  for (uint32_t v = 0; v < copies; ++v) {
    EXPECT_LT(std::abs(ksg[v]), 0.05) << "voxel " << v;
    EXPECT_LT(binned[v], 0.06) << "voxel " << v;
    EXPECT_GE(binned[v], 0.0) << "voxel " << v;
    mean += ksg[v] / copies;
  }
  EXPECT_LT(std::abs(mean), 0.02);
  // The copy itself (not shuffled) carries all of it: far above.
  const std::vector<float> self = kernel.compute(Ensemble({x}).view(), x, {CorrelationMeasure::MiKraskov, 16, 3});
  EXPECT_GT(self[0], 3.0);
}

TEST_F(CorrelationClosedForms, BivariateGaussianMatchesTheKnownMeasures) {
  const uint32_t members = 1000, samples = 8;
  std::mt19937 rng(1234);
  std::normal_distribution<double> normal;
  CorrelationKernel kernel(ctx());
  for (double rho : {0.0, 0.3, 0.6, 0.9}) {
    // Each voxel its own sample of (x, y); the reference is shared, so y = rho x + sqrt(1 - rho^2) z.
    std::vector<float> x(members);
    for (float& v : x) v = float(normal(rng));
    std::vector<std::vector<float>> s(samples, std::vector<float>(members));
    for (auto& y : s)
      for (uint32_t m = 0; m < members; ++m) y[m] = float(rho * x[m] + std::sqrt(1 - rho * rho) * normal(rng));
    const Ensemble e(s);
    auto mean_of = [&](const CorrelationParams& p) {
      const std::vector<float> g = kernel.compute(e.view(), x, p);
      return std::accumulate(g.begin(), g.end(), 0.0) / samples;
    };
    using std::numbers::pi;
    SCOPED_TRACE("rho = " + std::to_string(rho));
    // Standard errors of one sample are ~(1 - rho^2)/sqrt(M) <= 0.032 and of the mean of 8 a third
    // of that; the bounds are about 4 standard errors of the mean.
    EXPECT_NEAR(mean_of({CorrelationMeasure::Pearson}), rho, 0.045);
    EXPECT_NEAR(mean_of({CorrelationMeasure::Spearman}), 6 / pi * std::asin(rho / 2), 0.045);
    EXPECT_NEAR(mean_of({CorrelationMeasure::Kendall}), 2 / pi * std::asin(rho), 0.035);
    // KSG is nearly unbiased for Gaussians (Kraskov et al. 2004); its spread at M = 1000, k = 3
    // is ~0.015 per sample.
    const double mi = -0.5 * std::log(1 - rho * rho);
    const std::vector<float> ksg = kernel.compute(e.view(), x, {CorrelationMeasure::MiKraskov, 16, 3});
    EXPECT_NEAR(std::accumulate(ksg.begin(), ksg.end(), 0.0) / samples, mi, 0.03);
    // The coefficient is sqrt(1 - exp(-2 MI)) voxel by voxel, which is |rho| for a Gaussian. Only
    // for strong dependence is it checked against rho: near 0 its slope amplifies the MI's spread.
    const std::vector<float> coefficient = kernel.compute(e.view(), x, {CorrelationMeasure::MiCoefficient, 16, 3});
    for (uint32_t v = 0; v < samples; ++v)
      EXPECT_NEAR(coefficient[v], std::sqrt(1 - std::exp(-2 * std::max(double(ksg[v]), 0.0))), 1e-6) << "voxel " << v;
    if (rho >= 0.6) EXPECT_NEAR(mean_of({CorrelationMeasure::MiCoefficient, 16, 3}), rho, 0.03);
  }
}

}  // namespace
}  // namespace tfm
