// The correlation kernels (kernels/correlation.h) beyond their case table (host/selftest/
// selftest_correlation.cpp, run by test_kernel_cases.cpp: M = 3, 4, 31, 32, 33, 100, 1000 on
// 1 voxel, one past a workgroup and chunks, ties, a NaN member, a constant voxel, the reference
// voxel itself, against the double references): a two-valued reference, values computed by scipy
// and scikit-learn, bit-identical results across runs and chunkings, the device-memory budget,
// progress and input errors.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "correlation_expected.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/kernels/correlation_field.h"
#include "tfmatch/reference/correlation_cpu.h"
#include "tfmatch/selftest/selftest_support.h"
#include "tfmatch/shaders/correlation_layout.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

using selftest::bin_edge_ensemble;
using selftest::correlation_test_ensemble;
using selftest::CorrelationEnsemble;
using selftest::spread_ensemble;

const CorrelationParams kMeasures[] = {
    {CorrelationMeasure::Pearson},           {CorrelationMeasure::Spearman},
    {CorrelationMeasure::Kendall},           {CorrelationMeasure::MiBinned, 8},
    {CorrelationMeasure::MiKraskov, 16, 3},  {CorrelationMeasure::MiCoefficient, 16, 2},
};

// Mutual information is 0 for a constant series, the coefficients NaN (kernels/correlation.h).
bool is_mutual_information(const CorrelationParams& p) {
  return p.measure == CorrelationMeasure::MiBinned || p.measure == CorrelationMeasure::MiKraskov ||
         p.measure == CorrelationMeasure::MiCoefficient;
}

std::string measure_label(const CorrelationParams& p) {
  std::string s = correlation_measure_name(p.measure);
  for (char& c : s)
    if (c == '-') c = '_';
  return s;
}

class CorrelationGpu : public test::GpuTest, public ::testing::WithParamInterface<CorrelationParams> {};

// The members of `e` (a grid of `dims`) as slab readers, for correlation_field_streamed.
struct MemberSlabs {
  MemberSlabs(const CorrelationEnsemble& e, const std::array<uint64_t, 3>& dims) {
    for (uint32_t m = 0; m < e.members; ++m) {
      Volume v;
      v.dims = dims;
      v.values.assign(e.values.begin() + std::ptrdiff_t(m * e.voxels),
                      e.values.begin() + std::ptrdiff_t((m + 1) * e.voxels));
      owned.push_back(slabs_in_memory(std::move(v)));
      readers.push_back(owned.back().get());
    }
  }
  std::vector<std::unique_ptr<VolumeSlabReader>> owned;
  std::vector<VolumeSlabReader*> readers;
};

// Every voxel of `device` within `bound` of `expected`; NaN exactly where `expected` is NaN.
template <class T>
void expect_field_near(const std::vector<float>& device, const std::vector<T>& expected, double bound) {
  ASSERT_EQ(device.size(), expected.size());
  for (size_t v = 0; v < device.size(); ++v) {
    if (std::isnan(double(expected[v])))
      ASSERT_TRUE(std::isnan(device[v])) << "voxel " << v << ": device " << device[v] << ", expected NaN";
    else
      ASSERT_NEAR(device[v], expected[v], bound) << "voxel " << v;
  }
}

// A reference with two values, 500 members each: two huge x tie groups for kendall, and for
// mi-kraskov the longest neighbour walks (every point of its tie group lies at |dx| = 0), which
// must stay within what one invocation may loop on lavapipe.
TEST_P(CorrelationGpu, ReferenceWithTwoValues) {
  CorrelationParams params = GetParam();
  const uint32_t members = 1000;
  const CorrelationEnsemble e = correlation_test_ensemble(members, 9, 77);
  std::vector<float> reference(members);
  for (uint32_t m = 0; m < members; ++m) reference[m] = m % 2 ? 4.0f : 0.0f;
  CorrelationKernel kernel(ctx());
  const std::vector<float> g = kernel.compute(e.view(), reference, params);
  const std::vector<double> r = correlation_field_reference(e.view(), reference, params);
  expect_field_near(g, r, CorrelationKernel::error_bound(params, members));
}

// An infinite value in the reference series is a value for the rank measures (check_reference_point
// accepts it there: the kernel, the CPU peer and the double reference agree, and +-Inf rank as the
// largest and smallest values, as a finite value beyond every other would) and no value for the
// others (refused; needs_finite_members).
TEST_P(CorrelationGpu, InfiniteReferenceValues) {
  const CorrelationParams params = GetParam();
  for (uint32_t members : {9u, 40u}) {
    const CorrelationEnsemble e = correlation_test_ensemble(members, 50, 13);
    std::vector<float> reference = ensemble_series(e.view(), 7);
    std::vector<float> beyond = reference;
    reference[2] = INFINITY;
    reference[5] = -INFINITY;
    beyond[2] = 1e30f;
    beyond[5] = -1e30f;
    EnsembleView with_reference = e.view();
    std::vector<float> values = e.values;
    for (uint32_t m = 0; m < members; ++m) values[size_t(m) * e.voxels + 7] = reference[m];
    with_reference.values = values.data();
    if (needs_finite_members(params.measure)) {
      EXPECT_THROW(check_reference_point(with_reference, 7, params.measure), std::invalid_argument);
      continue;
    }
    EXPECT_NO_THROW(check_reference_point(with_reference, 7, params.measure));
    CorrelationKernel kernel(ctx());
    const std::vector<float> g = kernel.compute(e.view(), reference, params);
    const std::vector<double> r = correlation_field_reference(e.view(), reference, params);
    const std::vector<float> peer = correlation_field_cpu(e.view(), reference, params);
    const double bound = CorrelationKernel::error_bound(params, members);
    expect_field_near(g, r, bound);
    expect_field_near(peer, r, bound);
    if (params.measure == CorrelationMeasure::Spearman || params.measure == CorrelationMeasure::Kendall)
      expect_field_near(g, correlation_field_reference(e.view(), beyond, params), bound);
  }
}

TEST_P(CorrelationGpu, SameBitsOnEveryRunAndChunking) {
  const CorrelationParams params = GetParam();
  for (uint32_t members : {7u, 33u}) {
    const CorrelationEnsemble e = correlation_test_ensemble(members, 300, 5);
    const std::vector<float> reference = ensemble_series(e.view(), 17);
    CorrelationKernel kernel(ctx());
    const std::vector<float> a = kernel.compute(e.view(), reference, params);
    const std::vector<float> b = kernel.compute(e.view(), reference, params);
    uint32_t chunks = 0;
    const std::vector<float> c = kernel.compute(e.view(), reference, params, [&](uint64_t, uint64_t) { ++chunks; },
                                                uint64_t(members) * 16 + 16 + 41 * (uint64_t(members) * 8 + 8));
    EXPECT_EQ(chunks, 8u) << "41 voxels per chunk";
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0) << "M = " << members;
    EXPECT_EQ(std::memcmp(a.data(), c.data(), a.size() * sizeof(float)), 0) << "M = " << members;
  }
}

// Independent values (tests/host/reference/correlation_expected.py): the reference series x at
// voxel 0's place and y as the field's only voxel.
TEST_P(CorrelationGpu, MatchesScipyAndScikitLearn) {
  CorrelationParams params = GetParam();
  for (const test::ExpectedCorrelations& ex : test::expected_correlations()) {
    const EnsembleView view{ex.y.data(), uint32_t(ex.y.size()), 1};
    CorrelationKernel kernel(ctx());
    auto run = [&] { return double(kernel.compute(view, ex.x, params)[0]); };
    const double bound = CorrelationKernel::error_bound(params, view.member_count);
    switch (params.measure) {
      case CorrelationMeasure::Pearson: EXPECT_NEAR(run(), ex.pearson, bound) << ex.name; break;
      case CorrelationMeasure::Spearman: EXPECT_NEAR(run(), ex.spearman, bound) << ex.name; break;
      case CorrelationMeasure::Kendall: EXPECT_NEAR(run(), ex.kendall, bound) << ex.name; break;
      case CorrelationMeasure::MiBinned:
        params.bins = 4;
        EXPECT_NEAR(run(), ex.binned_4, bound) << ex.name;
        params.bins = 8;
        EXPECT_NEAR(run(), ex.binned_8, bound) << ex.name;
        break;
      case CorrelationMeasure::MiKraskov:
        params.k = 1;
        EXPECT_NEAR(run(), ex.ksg_k1, bound) << ex.name;
        params.k = 3;
        EXPECT_NEAR(run(), ex.ksg_k3, bound) << ex.name;
        break;
      case CorrelationMeasure::MiCoefficient:
        params.k = 3;
        EXPECT_NEAR(run(), std::sqrt(1 - std::exp(-2 * ex.ksg_k3)), bound) << ex.name;
        break;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Measures, CorrelationGpu, ::testing::ValuesIn(kMeasures),
                         [](const auto& info) { return measure_label(info.param); });

using CorrelationKernelGpu = test::GpuTest;

// Chunks keep the kernel's buffers within the budget; progress reports each chunk in order.
TEST_F(CorrelationKernelGpu, StaysWithinTheDeviceBudgetAndReportsProgress) {
  const uint32_t members = 100;
  const CorrelationEnsemble e = correlation_test_ensemble(members, 1000, 3);
  const std::vector<float> reference = e.reference();
  const uint64_t budget = 64 << 10;
  CorrelationKernel kernel(ctx());
  std::vector<uint64_t> done;
  const uint64_t before = ctx().buffer_bytes();
  ctx().reset_peak_buffer_bytes();
  kernel.compute(e.view(), reference, {CorrelationMeasure::Kendall},
                 [&](uint64_t d, uint64_t total) {
                   EXPECT_EQ(total, 1000u);
                   done.push_back(d);
                 },
                 budget);
  EXPECT_LE(ctx().peak_buffer_bytes() - before, budget);
  ASSERT_GT(done.size(), 10u);
  for (size_t i = 1; i < done.size(); ++i) EXPECT_GT(done[i], done[i - 1]);
  EXPECT_EQ(done.back(), 1000u);
}

// The field from members read slab by slab (correlation_field_streamed), for any slab size and any
// share of the z-slices (a rank's), is the whole ensemble's field bit for bit there, also for the
// difference of two points and its magnitude; a reference point without data is refused as by
// correlation_field().
TEST_F(CorrelationKernelGpu, StreamedSlabsGiveTheWholeEnsemblesBits) {
  const std::array<uint64_t, 3> dims{7, 5, 6};
  const uint32_t members = 9;
  const CorrelationEnsemble e = correlation_test_ensemble(members, 7 * 5 * 6, 21);
  const MemberSlabs slabs(e, dims);
  const std::vector<VolumeSlabReader*>& readers = slabs.readers;
  for (const CorrelationParams& params : kMeasures) {
    SCOPED_TRACE(correlation_measure_name(params.measure));
    for (const bool difference : {false, true}) {
      CorrelationRequest r;
      r.params = params;
      r.point = 2;  // a series with ties
      if (difference) r.point2 = 100, r.absolute = true;
      const std::vector<float> whole = correlation_field(ctx(), e.view(), r);
      for (uint64_t slab : {1u, 2u, 6u})
        for (auto [first, end] : {std::pair<uint64_t, uint64_t>{0, 6}, {2, 5}, {5, 6}}) {
          SCOPED_TRACE("slabs of " + std::to_string(slab) + ", slices " + std::to_string(first) + ".." + std::to_string(end) +
                       (difference ? ", |difference|" : ""));
          const std::vector<float> part = correlation_field_streamed(ctx(), readers, r, slab, first, end);
          ASSERT_EQ(part.size(), (end - first) * 35);
          EXPECT_EQ(0, std::memcmp(part.data(), whole.data() + first * 35, part.size() * sizeof(float)));
        }
    }
  }
  CorrelationRequest no_data;
  no_data.point = 5;  // a member is NaN there
  EXPECT_THROW(correlation_field_streamed(ctx(), readers, no_data, 2), std::invalid_argument);
  no_data.point = 7 * 5 * 6;  // past the grid
  EXPECT_THROW(correlation_field_streamed(ctx(), readers, no_data, 2), std::invalid_argument);
}

// prepare() (which the CLI calls before it sizes slabs from the memory left) runs the kernel once
// on a voxel of its own: afterwards the kernel gives a fresh kernel's bits, also as the caller's
// kernel of correlation_field_streamed, and it refuses what compute() refuses.
TEST_F(CorrelationKernelGpu, PreparedKernelGivesAFreshKernelsBits) {
  const std::array<uint64_t, 3> dims{7, 5, 6};
  const uint32_t members = 9;
  const CorrelationEnsemble e = correlation_test_ensemble(members, 7 * 5 * 6, 21);
  const MemberSlabs slabs(e, dims);
  for (const CorrelationParams& params : kMeasures) {
    SCOPED_TRACE(correlation_measure_name(params.measure));
    CorrelationKernel prepared(ctx()), fresh(ctx());
    prepared.prepare(params, members);
    const std::vector<float> a = prepared.compute(e.view(), e.reference(), params);
    const std::vector<float> b = fresh.compute(e.view(), e.reference(), params);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(float)));
    CorrelationRequest r;
    r.params = params;
    r.point = 2;
    const std::vector<float> whole = correlation_field(ctx(), e.view(), r);
    const std::vector<float> streamed = correlation_field_streamed(prepared, slabs.readers, r, 2);
    ASSERT_EQ(streamed.size(), whole.size());
    EXPECT_EQ(0, std::memcmp(streamed.data(), whole.data(), whole.size() * sizeof(float)));
  }
  CorrelationKernel kernel(ctx());
  EXPECT_THROW(kernel.prepare({CorrelationMeasure::Pearson}, 2), std::invalid_argument);  // under 3 members
  CorrelationParams bins{CorrelationMeasure::MiBinned};
  bins.bins = 1000;
  EXPECT_THROW(kernel.prepare(bins, members), std::invalid_argument);
}

// A NaN in the reference series: NaN everywhere, without touching the device.
TEST_F(CorrelationKernelGpu, NanReferenceGivesNanEverywhere) {
  const CorrelationEnsemble e = correlation_test_ensemble(40, 20, 9);
  std::vector<float> reference = e.reference();
  reference[3] = NAN;
  CorrelationKernel kernel(ctx());
  for (const CorrelationParams& p : kMeasures)
    for (float v : kernel.compute(e.view(), reference, p)) EXPECT_TRUE(std::isnan(v)) << correlation_measure_name(p.measure);
}

// An infinite member leaves pearson (the mean is infinite), mi-binned (equal-width bins over an
// infinite range) and the Kraskov measures (no finite neighbour distances) without a value: NaN,
// as NaN does (needs_finite_members), whether it is the first member (pearson's shift) or
// another, +Inf or -Inf, and in the reference series too; the CPU peer and the double reference
// agree. Before 2026-12-04 the kernels gave pearson -1 (its shifted sums turned NaN and clamp()
// took the lower end) and mi-binned 0 for a -Inf member, where the peer gave a number; before
// 2026-12-06 mi-kraskov's kernel and peer gave 0.154 where the double reference gave 0.282 (an
// infinite reference member, M = 9). Every other voxel keeps the bits it has without the
// infinities.
TEST_F(CorrelationKernelGpu, InfiniteMembersLeaveMeansBinsAndNeighboursWithoutAValue) {
  CorrelationKernel kernel(ctx());
  uint32_t measures = 0;
  for (const CorrelationParams& p : kMeasures) {
    if (!needs_finite_members(p.measure)) continue;
    ++measures;
    const std::string name = correlation_measure_name(p.measure);
    for (uint32_t members : {9u, 40u}) {
      const CorrelationEnsemble plain = correlation_test_ensemble(members, 20, 4);
      CorrelationEnsemble e = plain;
      e.values[0 * e.voxels + 9] = INFINITY;  // the first member: the one pearson shifts by
      e.values[3 * e.voxels + 10] = -INFINITY;
      e.values[(members - 1) * e.voxels + 11] = INFINITY;  // the last
      const std::vector<float> reference = plain.reference();
      const std::vector<float> gpu = kernel.compute(e.view(), reference, p);
      const std::vector<float> peer = correlation_field_cpu(e.view(), reference, p);
      const std::vector<double> exact = correlation_field_reference(e.view(), reference, p);
      const std::vector<float> before = kernel.compute(plain.view(), reference, p);
      for (uint64_t v = 0; v < e.voxels; ++v) {
        if (v >= 9 && v <= 11) {
          EXPECT_TRUE(std::isnan(peer[v])) << name << ": the CPU peer at voxel " << v << ": " << peer[v];
          EXPECT_TRUE(std::isnan(exact[v])) << name << ": the double reference at voxel " << v << ": " << exact[v];
          EXPECT_TRUE(std::isnan(gpu[v])) << name << ", " << members << " members, voxel " << v << ": " << gpu[v];
        } else {
          EXPECT_EQ(0, std::memcmp(&gpu[v], &before[v], sizeof(float)))
              << name << ", voxel " << v << ": " << gpu[v] << " vs " << before[v];
        }
      }
      std::vector<float> infinite_reference = reference;
      infinite_reference[2] = -INFINITY;
      for (float v : kernel.compute(plain.view(), infinite_reference, p)) EXPECT_TRUE(std::isnan(v)) << name;
      for (float v : correlation_field_cpu(plain.view(), infinite_reference, p)) EXPECT_TRUE(std::isnan(v)) << name;
      for (double v : correlation_field_reference(plain.view(), infinite_reference, p))
        EXPECT_TRUE(std::isnan(v)) << name;
    }
  }
  EXPECT_EQ(measures, 4u) << "pearson, mi-binned, mi-kraskov, mi-coefficient";
}

// A constant reference: NaN for the coefficients, 0 for mutual information; NaN members stay NaN.
TEST_F(CorrelationKernelGpu, ConstantReferenceFollowsTheConventions) {
  for (uint32_t members : {9u, 40u}) {
    const CorrelationEnsemble e = correlation_test_ensemble(members, 10, 4);
    const std::vector<float> reference(members, 2.5f);
    CorrelationKernel kernel(ctx());
    for (const CorrelationParams& p : kMeasures) {
      const std::vector<float> g = kernel.compute(e.view(), reference, p);
      for (uint64_t v = 0; v < g.size(); ++v) {
        if (v == 5 || !is_mutual_information(p)) EXPECT_TRUE(std::isnan(g[v])) << correlation_measure_name(p.measure) << " voxel " << v;
        else EXPECT_EQ(g[v], 0.0f) << correlation_measure_name(p.measure) << " voxel " << v;
      }
    }
  }
}

TEST_F(CorrelationKernelGpu, RejectsBadInputWithClearMessages) {
  CorrelationKernel kernel(ctx());
  const CorrelationEnsemble e = correlation_test_ensemble(10, 4, 1);
  const std::vector<float> reference = e.reference();
  auto message = [&](const EnsembleView& view, std::span<const float> ref, const CorrelationParams& p,
                     uint64_t budget = 0) -> std::string {
    try {
      kernel.compute(view, ref, p, {}, budget);
    } catch (const std::invalid_argument& ex) {
      return ex.what();
    }
    return "no exception";
  };
  const EnsembleView two{e.values.data(), 2, 4};
  EXPECT_NE(message(two, std::span(reference).first(2), {}).find("needs 3..16384 members (got 2)"), std::string::npos);
  EXPECT_NE(message(e.view(), std::span(reference).first(9), {}).find("9 values for 10 members"), std::string::npos);
  EXPECT_NE(message(e.view(), reference, {CorrelationMeasure::MiBinned, 1}).find("bins must be 2..64"), std::string::npos);
  EXPECT_NE(message(e.view(), reference, {CorrelationMeasure::MiBinned, 65}).find("bins"), std::string::npos);
  EXPECT_NE(message(e.view(), reference, {CorrelationMeasure::MiKraskov, 16, 0}).find("k must be 1..9"), std::string::npos);
  EXPECT_NE(message(e.view(), reference, {CorrelationMeasure::MiKraskov, 16, 10}).find("k must be"), std::string::npos);
  EXPECT_NE(message(e.view(), reference, {}, 100).find("max_device_bytes"), std::string::npos);
  EXPECT_NE(message({nullptr, 10, 4}, reference, {}).find("no voxels"), std::string::npos);
  const std::vector<float> too_many(kMaxCorrelationMembers + 1);
  EXPECT_NE(message({too_many.data(), kMaxCorrelationMembers + 1, 1}, too_many, {}).find("(got 16385)"), std::string::npos);
  // More members than the device's workgroups hold: a runtime error naming the limit (shared
  // memory: lavapipe's 32 KiB, most GPUs' 48 KiB).
  const std::vector<float> many(kMaxCorrelationMembers, 1.0f);
  for (const CorrelationParams& p : {CorrelationParams{CorrelationMeasure::Kendall}, {CorrelationMeasure::MiKraskov}}) {
    const uint32_t max_workgroup = CorrelationKernel::max_workgroup(ctx());
    const bool fits = CorrelationKernel::shared_memory_bytes(p, kMaxCorrelationMembers, max_workgroup) <=
                          ctx().limits().maxComputeSharedMemorySize &&
                      CorrelationKernel::workgroup_size(p, kMaxCorrelationMembers, max_workgroup) <= max_workgroup;
    if (fits) continue;
    try {
      kernel.compute({many.data(), kMaxCorrelationMembers, 1}, many, p);
      ADD_FAILURE() << "no exception for " << kMaxCorrelationMembers << " members";
    } catch (const std::runtime_error& ex) {
      EXPECT_NE(std::string(ex.what()).find(std::string(correlation_measure_name(p.measure)) + " with 16384 members needs"),
                std::string::npos) << ex.what();
      EXPECT_NE(std::string(ex.what()).find("maxCompute"), std::string::npos) << ex.what();
    }
  }
}

// mi-binned written here from its definition (kernels/correlation.h and the header of
// shaders/correlation_mi_binned.comp), not from the CPU peer, which shares the kernels' prepared
// reference series (prepare_correlation_reference): the plug-in estimate in double from the raw
// member series. Only the binning keeps float arithmetic, because the definition does: the bin of
// v is the largest b < B with b (hi - lo) <= (v - lo) B, every operation a correctly rounded float
// one (computed exactly in double and rounded to float once). Exact real arithmetic would bin the
// values within an ulp of an edge, which these tests are about, differently from that rule.
uint32_t bin_by_definition(float value, float lo, float hi, uint32_t bins) {
  const float range = float(double(hi) - double(lo));
  const float scaled = float(double(float(double(value) - double(lo))) * double(bins));
  uint32_t b = 0;
  while (b + 1 < bins && float(double(b + 1) * double(range)) <= scaled) ++b;
  return b;
}
std::vector<double> mi_binned_by_definition(const EnsembleView& ens, std::span<const float> reference, uint32_t bins) {
  const uint32_t n = ens.member_count;
  auto bins_of = [&](const std::vector<float>& v, std::vector<uint32_t>& out) {
    const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
    out.resize(v.size());
    for (size_t m = 0; m < v.size(); ++m) out[m] = bin_by_definition(v[m], *lo, *hi, bins);
    return *lo != *hi;
  };
  auto any_nan = [](const std::vector<float>& v) { return std::any_of(v.begin(), v.end(), [](float f) { return std::isnan(f); }); };
  const std::vector<float> x(reference.begin(), reference.end());
  std::vector<uint32_t> bx, by;
  const bool x_varies = bins_of(x, bx);
  std::vector<double> out(ens.voxel_count);
  std::vector<float> y(n);
  for (uint64_t v = 0; v < ens.voxel_count; ++v) {
    for (uint32_t m = 0; m < n; ++m) y[m] = ens.at(m, v);
    if (any_nan(x) || any_nan(y)) {
      out[v] = std::nan("");
      continue;
    }
    // A constant series carries no information (kernels/correlation.h).
    if (!bins_of(y, by) || !x_varies) {
      out[v] = 0.0;
      continue;
    }
    std::vector<double> joint(size_t(bins) * bins, 0.0), cx(bins, 0.0), cy(bins, 0.0);
    for (uint32_t m = 0; m < n; ++m) joint[bx[m] * bins + by[m]] += 1, cx[bx[m]] += 1, cy[by[m]] += 1;
    double mi = 0.0;
    for (uint32_t i = 0; i < bins; ++i)
      for (uint32_t j = 0; j < bins; ++j)
        if (const double c = joint[i * bins + j]; c > 0) mi += c / n * std::log(c * n / (cx[i] * cy[j]));
    out[v] = mi;
  }
  return out;
}

// Member values within 4 ulp of the edges of 10 bins over a range of 3 (k * 3 / 10 in float):
// which bin such a value falls into is decided by float products, never by a division (Vulkan
// allows 2.5 ulp there), so the kernel counts as the definition says on every device. NVIDIA's
// driver put edge values into other bins than the CPU and was 0.017 off at 100 members before.
// The CPU peer, which the benchmark compares with, must count so too.
TEST_F(CorrelationKernelGpu, MiBinnedCountsValuesOnBinEdgesAsTheCpuPeer) {
  const CorrelationParams params{CorrelationMeasure::MiBinned, 10};
  // Both strategies: one invocation per voxel up to TFM_CORR_MI_BINNED_INVOCATION_MAX_MEMBERS.
  for (const uint32_t members : {30u, 100u, TFM_CORR_MI_BINNED_INVOCATION_MAX_MEMBERS + 1}) {
    SCOPED_TRACE(members);
    const CorrelationEnsemble e = bin_edge_ensemble(members, 500);
    const std::vector<float> reference = e.reference();
    const std::vector<float> g = CorrelationKernel(ctx()).compute(e.view(), reference, params);
    const std::vector<double> expected = mi_binned_by_definition(e.view(), reference, params.bins);
    const double bound = CorrelationKernel::error_bound(params, members);
    expect_field_near(g, expected, bound);
    expect_field_near(correlation_field_cpu(e.view(), reference, params), expected, bound);
  }
}

// The Kraskov plans grow their workgroups until each invocation's neighbour searches stay within
// llvmpipe's loop limit, and never beyond what the device allows (a device whose workgroups hold
// fewer than 1024 invocations ran none of the larger plans before 2026-12-06, though it has no
// loop limit). The figures: M = 1000 with k = 3 needs ceil(1000 / T) * 5043 loop iterations within
// 49152, so T = 128; k = 9 (11 a step) T = 256; M = 1409, k = 9: T = 512.
TEST(CorrelationPlan, KraskovWorkgroupsGrowWithTheSearchesWithinTheDevicesLimit) {
  const CorrelationParams k3{CorrelationMeasure::MiKraskov, 16, 3}, k9{CorrelationMeasure::MiKraskov, 16, 9};
  EXPECT_EQ(CorrelationKernel::workgroup_size(k3, 1000), 128u);
  EXPECT_EQ(CorrelationKernel::workgroup_size(k9, 1000), 256u);
  EXPECT_EQ(CorrelationKernel::workgroup_size(k9, 1409), 512u);
  EXPECT_EQ(CorrelationKernel::workgroup_size(k3, 1000, 64), 64u);
  EXPECT_EQ(CorrelationKernel::workgroup_size(k9, 1409, 256), 256u);
  EXPECT_LT(CorrelationKernel::shared_memory_bytes(k9, 1409, 256), CorrelationKernel::shared_memory_bytes(k9, 1409));
  // The sort-based measures keep one subgroup's worth whatever the limit.
  EXPECT_EQ(CorrelationKernel::workgroup_size({CorrelationMeasure::Spearman}, 1000, 32), 32u);
}

// One kernel object, one member count, two k: two workgroup sizes, two pipelines, each k with a
// fresh kernel's bits. Before 2026-12-06 the pipelines were kept by region size alone, so k = 9
// after k = 1 ran k = 1's 64 invocations where its plan had 256: other sums' order, and on
// lavapipe, for data whose searches walk further, past the loop limit.
TEST_F(CorrelationKernelGpu, KraskovKeepsAPipelinePerWorkgroupAtOneMemberCount) {
  const CorrelationEnsemble e = spread_ensemble(1000, 11);
  const std::vector<float> reference = e.reference();
  CorrelationKernel kernel(ctx());
  const uint32_t max_workgroup = CorrelationKernel::max_workgroup(ctx());
  for (const uint32_t k : {1u, 9u}) {
    SCOPED_TRACE(k);
    const CorrelationParams params{CorrelationMeasure::MiKraskov, 16, k};
    const std::vector<float> g = kernel.compute(e.view(), reference, params);
    const std::vector<float> fresh = CorrelationKernel(ctx()).compute(e.view(), reference, params);
    EXPECT_EQ(std::memcmp(g.data(), fresh.data(), g.size() * sizeof(float)), 0);
    expect_field_near(g, correlation_field_reference(e.view(), reference, params),
                      CorrelationKernel::error_bound(params, 1000, max_workgroup));
  }
  EXPECT_EQ(CorrelationKernel::workgroup_size({CorrelationMeasure::MiKraskov, 16, 1}, 1000, max_workgroup), 64u);
}

// A plan made for smaller workgroups than the searches need: a device without a loop limit runs
// it (same values within the bound of its own plan); llvmpipe refuses it, naming the loop
// iterations (16 searches of 5043 each at T = 64), and computes nothing.
TEST_F(CorrelationKernelGpu, KraskovWithinSmallerWorkgroupsRunsOrRefusesByTheLoopLimit) {
  const CorrelationEnsemble e = spread_ensemble(1000, 12);
  const std::vector<float> reference = e.reference();
  const CorrelationParams params{CorrelationMeasure::MiKraskov, 16, 3};
  CorrelationKernel kernel(ctx(), 64);
  if (ctx().loop_iteration_limit() == 0) {
    expect_field_near(kernel.compute(e.view(), reference, params),
                      correlation_field_reference(e.view(), reference, params),
                      CorrelationKernel::error_bound(params, 1000, 64));
    return;
  }
  try {
    kernel.compute(e.view(), reference, params);
    ADD_FAILURE() << "no exception for 64 invocations of 16 searches each";
  } catch (const std::runtime_error& ex) {
    const std::string what = ex.what();
    EXPECT_NE(what.find("mi-kraskov with 1000 members needs up to 80688 loop iterations"), std::string::npos) << what;
    EXPECT_NE(what.find("after 65535 (llvmpipe)"), std::string::npos) << what;
  }
  // Within the device's own limit the same kernel class plans 128 invocations and runs.
  expect_field_near(CorrelationKernel(ctx(), 128).compute(e.view(), reference, params),
                    correlation_field_reference(e.view(), reference, params),
                    CorrelationKernel::error_bound(params, 1000, 128));
}

// More workgroups than one dispatch row holds (maxComputeWorkGroupCount[0], 65535 on lavapipe):
// the rows of a 2-D dispatch cover every voxel once.
TEST_F(CorrelationKernelGpu, ChunksOfMoreGroupsThanOneRowHolds) {
  const CorrelationParams params{CorrelationMeasure::Spearman};  // at 33 members one workgroup per voxel
  const uint32_t row = ctx().limits().maxComputeWorkGroupCount[0];
  // GPUs hold 2^31 - 1 groups in a row: more voxels than that do not fit one test.
  if (row > (1u << 20)) GTEST_SKIP() << "one dispatch row holds " << row << " workgroups on this device";
  const uint64_t voxels = uint64_t(row) + 300;
  const CorrelationEnsemble e = correlation_test_ensemble(33, voxels, 8);
  const std::vector<float> reference = e.reference();
  CorrelationKernel kernel(ctx());
  uint32_t chunks = 0;
  const std::vector<float> g = kernel.compute(e.view(), reference, params, [&](uint64_t, uint64_t) { ++chunks; });
  ASSERT_EQ(chunks, 1u);
  expect_field_near(g, correlation_field_reference(e.view(), reference, params),
                    CorrelationKernel::error_bound(params, 33));
}

}  // namespace
}  // namespace tfm
