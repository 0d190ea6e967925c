// Closed forms of the correlation measures on the GPU kernels: a monotone transform of the
// reference gives Spearman = Kendall = 1 (-1 decreasing); an independent shuffled copy gives
// mutual information near 0; a bivariate Gaussian with correlation rho gives Pearson ~ rho,
// Spearman ~ (6/pi) asin(rho/2), Kendall ~ (2/pi) asin(rho), Kraskov MI ~ -ln(1 - rho^2)/2 and
// its coefficient ~ |rho|, within the sampling error of M = 1000 members; Pearson and Spearman on
// enough samples that the tolerance tells their two closed forms apart.
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "tfmatch/kernels/correlation.h"
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
    // Pearson and Spearman: PearsonAndSpearmanTellTheirClosedFormsApart, on more samples.
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

// Pearson's mean is rho and Spearman's (6/pi) asin(rho/2), which differ by only 0.0085 to 0.018
// for rho in {0.3, 0.6, 0.9}: the tolerance must be under half that difference, so that a kernel
// computing either closed form's measure in place of the other fails (checked below, live).
// Standard error of one sample (M members; Fisher's z, and Bonett & Wright 2000 for Spearman):
//   Pearson (1 - rho^2) / sqrt(M - 3),  Spearman (1 - rho_s^2) sqrt((1 + rho_s^2 / 2) / (M - 3)).
// The voxels of one kernel call share their reference series, so their errors are correlated;
// a mean of correlated samples of equal variance has at most that variance, so the mean over
// kBatches calls, each with its own reference, has a standard error of at most sigma /
// sqrt(kBatches) whatever the voxels per call add. The tolerance is 4 of those. The sample
// means' own bias (Pearson's rho (1 - rho^2) / 2M, Spearman's exact expectation's 3e-4 at M =
// 1000) is far below it.
TEST_F(CorrelationClosedForms, PearsonAndSpearmanTellTheirClosedFormsApart) {
  constexpr uint32_t kMembers = 1000, kBatches = 512, kPerRho = 4;
  const std::vector<double> rhos = {0.0, 0.3, 0.6, 0.9};
  using std::numbers::pi;
  auto pearson_form = [](double rho) { return rho; };
  auto spearman_form = [](double rho) { return 6 / pi * std::asin(rho / 2); };
  auto tolerance = [&](CorrelationMeasure m, double rho) {
    const double r = m == CorrelationMeasure::Pearson ? pearson_form(rho) : spearman_form(rho);
    const double spread = m == CorrelationMeasure::Pearson ? 1.0 : std::sqrt(1 + r * r / 2);
    const double sigma = (1 - r * r) * spread / std::sqrt(double(kMembers - 3));
    return 4 * sigma / std::sqrt(double(kBatches)) + CorrelationKernel::error_bound({m}, kMembers);
  };
  std::mt19937 rng(4321);
  std::normal_distribution<double> normal;
  CorrelationKernel kernel(ctx());
  // Sums of the voxels' values per measure (Pearson, Spearman) and rho.
  std::vector<std::array<double, 2>> sums(rhos.size(), {0.0, 0.0});
  for (uint32_t b = 0; b < kBatches; ++b) {
    std::vector<double> x(kMembers);
    for (double& v : x) v = normal(rng);
    const std::vector<float> xf(x.begin(), x.end());
    std::vector<std::vector<float>> s;
    for (double rho : rhos)
      for (uint32_t k = 0; k < kPerRho; ++k) {
        std::vector<float> y(kMembers);
        for (uint32_t m = 0; m < kMembers; ++m) y[m] = float(rho * x[m] + std::sqrt(1 - rho * rho) * normal(rng));
        s.push_back(std::move(y));
      }
    const Ensemble e(s);
    for (int which = 0; which < 2; ++which) {
      const std::vector<float> g =
          kernel.compute(e.view(), xf, {which == 0 ? CorrelationMeasure::Pearson : CorrelationMeasure::Spearman});
      for (size_t r = 0; r < rhos.size(); ++r)
        for (uint32_t k = 0; k < kPerRho; ++k) sums[r][size_t(which)] += g[r * kPerRho + k];
    }
  }
  for (size_t r = 0; r < rhos.size(); ++r) {
    const double rho = rhos[r];
    SCOPED_TRACE("rho = " + std::to_string(rho));
    const double pearson = sums[r][0] / (kBatches * kPerRho), spearman = sums[r][1] / (kBatches * kPerRho);
    const double tol_p = tolerance(CorrelationMeasure::Pearson, rho), tol_s = tolerance(CorrelationMeasure::Spearman, rho);
    EXPECT_NEAR(pearson, pearson_form(rho), tol_p);
    EXPECT_NEAR(spearman, spearman_form(rho), tol_s);
    if (rho == 0.0) continue;  // both forms are 0 there
    const double gap = std::abs(pearson_form(rho) - spearman_form(rho));
    // Within tol of the right form and gap > 2 tol: more than tol from the wrong one, always.
    EXPECT_GT(gap, 2 * tol_p) << "the Pearson tolerance cannot tell the forms apart";
    EXPECT_GT(gap, 2 * tol_s) << "the Spearman tolerance cannot tell the forms apart";
    EXPECT_GT(std::abs(pearson - spearman_form(rho)), tol_p) << "Pearson's mean passes for Spearman's form";
    EXPECT_GT(std::abs(spearman - pearson_form(rho)), tol_s) << "Spearman's mean passes for Pearson's form";
  }
}

}  // namespace
}  // namespace tfm
