// Self-test cases of the correlation kernels (correlation_pearson, _spearman, _kendall,
// _mi_binned, _mi_kraskov): every measure on both strategies (one invocation per voxel at
// M <= 32, one workgroup per voxel above), with ties, a NaN member, a constant voxel, the
// reference voxel itself and fields split into chunks, and Pearson's shifted one pass at its worst,
// against the double-precision references.
#include <algorithm>
#include <cmath>
#include <string>

#include "tfmatch/kernels/correlation.h"
#include "tfmatch/reference/correlation_cpu.h"
#include "tfmatch/selftest/selftest_support.h"
#include "tfmatch/shaders/correlation_layout.h"

namespace tfm::selftest {
namespace {

struct CorrelationCase {
  CorrelationParams params;
  uint32_t members;
  uint64_t voxels;
  uint64_t max_device_bytes = 0;  // small: several chunks
  // mixed: correlation_test_ensemble; bin_edges: bin_edge_ensemble, against the CPU peer's float
  // binning; pearson_shift: pearson_shift_ensemble about 0, pearson_shift_offset about 1000.
  // spread: spread_ensemble, series a thousand times wider (and narrower) than the reference.
  enum class Data { mixed, bin_edges, pearson_shift, pearson_shift_offset, spread } data = Data::mixed;
  // The voxel whose series is the reference: 0 is the ensemble's reference series; 2 a series
  // rounded to multiples of 1/4, so the reference has many ties (kendall's x tie groups, repeated
  // Kraskov points).
  uint64_t reference_voxel = 0;
};

bool is_mutual_information(const CorrelationParams& p) {
  return p.measure == CorrelationMeasure::MiBinned || p.measure == CorrelationMeasure::MiKraskov ||
         p.measure == CorrelationMeasure::MiCoefficient;
}

// Bound: CorrelationKernel::error_bound (the mixed data make every comparison exact in float).
// NaN results must be NaN on both sides. The data reach the conventions, which the field must
// follow: NaN at the voxel with a NaN member (5), NaN (or 0 for mutual information) at the
// constant voxel (7), 1 at the reference voxel for pearson, spearman and kendall; for pearson,
// mi-binned and the Kraskov measures NaN at a voxel with an infinite member too (9, where the
// grid has it: needs_finite_members).
void correlation(Context& ctx, Check& check, CorrelationCase c) {
  c.params.k = std::min(c.params.k, c.members - 1);  // k < M
  const uint32_t max_workgroup = CorrelationKernel::max_workgroup(ctx);
  if (const uint64_t bytes = CorrelationKernel::shared_memory_bytes(c.params, c.members, max_workgroup);
      !fits_shared_memory(ctx, bytes))
    return check.skip(needs_shared_memory(ctx, bytes));
  const uint32_t seed = 7u * c.members + uint32_t(c.voxels);
  using Data = CorrelationCase::Data;
  const bool bin_edges = c.data == Data::bin_edges, mixed = c.data == Data::mixed;
  const float shift_offset = c.data == Data::pearson_shift_offset ? 1000.0f : 0.0f;
  CorrelationEnsemble e = bin_edges                 ? bin_edge_ensemble(c.members, c.voxels)
                          : mixed                     ? correlation_test_ensemble(c.members, c.voxels, seed)
                          : c.data == Data::spread    ? spread_ensemble(c.members, seed)
                                                      : pearson_shift_ensemble(c.members, shift_offset, seed);
  const bool infinite_member =
      mixed && needs_finite_members(c.params.measure) && c.voxels > 9 && c.reference_voxel != 9;
  if (infinite_member) e.values[2 * e.voxels + 9] = INFINITY;
  const std::vector<float> reference = ensemble_series(e.view(), c.reference_voxel);
  CorrelationKernel kernel(ctx);
  uint32_t chunks = 0;
  const std::vector<float> g =
      kernel.compute(e.view(), reference, c.params, [&](uint64_t, uint64_t) { ++chunks; }, c.max_device_bytes);
  if (c.max_device_bytes) check.require(chunks > 1, "the ensemble was not split into chunks");
  // Values on bin edges: the binning is a convention (float products, correlation_mi_binned.comp)
  // that the double reference does not follow, so the CPU peer, which does, is the reference.
  std::vector<double> r;
  if (bin_edges) {
    const std::vector<float> peer = correlation_field_cpu(e.view(), reference, c.params);
    r.assign(peer.begin(), peer.end());
  } else {
    r = correlation_field_reference(e.view(), reference, c.params);
  }
  const double bound = CorrelationKernel::error_bound(c.params, c.members, max_workgroup);
  for (uint64_t v = 0; v < e.voxels; ++v) {
    if (std::isnan(r[v]))
      check.equal("NaN voxel (1: NaN)", v, std::isnan(g[v]) ? 1.0 : 0.0, 1.0);
    else
      check.near("voxel", v, g[v], r[v], bound);
  }
  if (mixed && c.voxels > 7) {
    check.require(std::isnan(g[5]), "the voxel with a NaN member is not NaN");
    check.require(is_mutual_information(c.params) ? g[7] == 0.0f : std::isnan(g[7]),
                  "the constant voxel does not follow the convention");
  }
  if (infinite_member) check.require(std::isnan(g[9]), "the voxel with an infinite member is not NaN");
  if (c.params.measure == CorrelationMeasure::Pearson || c.params.measure == CorrelationMeasure::Spearman ||
      c.params.measure == CorrelationMeasure::Kendall)
    check.near("the reference voxel itself", c.reference_voxel, g[c.reference_voxel], 1.0, bound);
}

std::string correlation_name(const CorrelationCase& c) {
  using Data = CorrelationCase::Data;
  if (c.data == Data::pearson_shift || c.data == Data::pearson_shift_offset)
    return "M=" + std::to_string(c.members) + ", first member's shift ratio 0 to " +
           std::to_string(int(0.999 * (c.members - 1))) + " (limit " +
           std::to_string(int(TFM_CORR_PEARSON_SHIFT_LIMIT)) + ")" +
           (c.data == Data::pearson_shift_offset ? ", values about 1000" : "");
  std::string s = "M=" + std::to_string(c.members) + ", " + voxels_name(c.voxels);
  if (c.params.measure == CorrelationMeasure::MiBinned) s += ", " + std::to_string(c.params.bins) + " bins";
  if (c.params.measure == CorrelationMeasure::MiKraskov) s += ", k=" + std::to_string(c.params.k);
  if (c.params.measure == CorrelationMeasure::MiCoefficient) s += ", coefficient, k=" + std::to_string(c.params.k);
  if (c.max_device_bytes) s += ", chunks";
  if (c.data == Data::bin_edges) s += ", values within 4 ulp of bin edges";
  if (c.data == Data::spread) s += ", series 1000 times wider and narrower than the reference";
  if (c.reference_voxel) s += ", reference with ties (voxel " + std::to_string(c.reference_voxel) + ")";
  return s;
}

}  // namespace

void add_correlation_cases(CaseList& cases) {
  using M = CorrelationMeasure;
  const struct {
    const char* shader;
    CorrelationParams params;
  } measures[] = {
      {"correlation_pearson", {M::Pearson}},
      {"correlation_spearman", {M::Spearman}},
      {"correlation_kendall", {M::Kendall}},
      {"correlation_mi_binned", {M::MiBinned, 8}},
      {"correlation_mi_kraskov", {M::MiKraskov, 16, 3}},
      {"correlation_mi_kraskov", {M::MiCoefficient, 16, 4}},
      {"correlation_mi_kraskov", {M::MiCoefficient, 16, 2}},
  };
  for (const auto& m : measures) {
    auto add = [&](uint32_t members, uint64_t voxels, uint64_t max_bytes, bool quick, uint64_t reference_voxel = 0) {
      const CorrelationCase c{m.params, members, voxels, max_bytes, CorrelationCase::Data::mixed, reference_voxel};
      cases.push_back({m.shader, "CorrelationKernel", correlation_name(c), quick,
                       CorrelationKernel::workgroup_size(m.params, members),
                       [c](Context& ctx, Check& check) { correlation(ctx, check, c); }});
    };
    // One invocation per voxel: one past a workgroup of voxels, in chunks (4 KiB hold ~60 voxels).
    add(7, TFM_CORR_INVOCATION_WORKGROUP + 1, 4096, true);
    // One workgroup per voxel (mi-binned: still one invocation); the paper's 1000 members on a few voxels.
    add(100, 9, 0, true);
    add(33, 13, 0, false);
    add(1000, 9, 0, false);
    add(1000, 9, 0, false, 2);
    // Awkward member counts around one subgroup and either strategy, on 1 voxel and one past a
    // workgroup of voxels, the latter also with a tied reference.
    const uint64_t past_workgroup = TFM_CORR_INVOCATION_WORKGROUP + 1;
    for (uint32_t members : {3u, 4u, 31u, 32u, 33u}) {
      add(members, 1, 0, true);
      add(members, past_workgroup, 0, true);
      add(members, past_workgroup, 0, true, 2);
    }
    // mi-binned counts per x bin in one invocation up to its own limit: either side of it.
    if (m.params.measure == M::MiBinned)
      for (uint32_t members : {TFM_CORR_MI_BINNED_INVOCATION_MAX_MEMBERS, TFM_CORR_MI_BINNED_INVOCATION_MAX_MEMBERS + 1})
        add(members, 9, 0, false);
  }
  // mi-binned on values within 4 ulp of its bin edges, on both strategies: every device must bin
  // them as the CPU peer does (a division-decided binning did not on NVIDIA's driver 580).
  for (const uint32_t members : {30u, 100u, TFM_CORR_MI_BINNED_INVOCATION_MAX_MEMBERS + 1}) {
    const CorrelationCase c{{CorrelationMeasure::MiBinned, 10}, members, 300, 0, CorrelationCase::Data::bin_edges};
    cases.push_back({"correlation_mi_binned", "CorrelationKernel", correlation_name(c), members == 30,
                     CorrelationKernel::workgroup_size(c.params, members),
                     [c](Context& ctx, Check& check) { correlation(ctx, check, c); }});
  }
  // Kraskov searches that walk past nearly every member (the k nearest decided by a series far
  // wider than the reference): before 2026-12-06 the workgroup was sized for one loop iteration a
  // step, and lavapipe ended the searches early (0.09 nats for 0.002). At M = 1409, k = 9 (11 loop
  // iterations a step) 512 invocations of 3 searches each stay within the budget, and within
  // 32 KiB of shared memory.
  for (const auto& [members, k] : {std::pair{1000u, 3u}, std::pair{1409u, 9u}}) {
    const CorrelationCase c{{CorrelationMeasure::MiKraskov, 16, k}, members, 4, 0, CorrelationCase::Data::spread};
    cases.push_back({"correlation_mi_kraskov", "CorrelationKernel", correlation_name(c), false,
                     CorrelationKernel::workgroup_size(c.params, members),
                     [c](Context& ctx, Check& check) { correlation(ctx, check, c); }});
  }
  // Pearson's one pass and its second pass for series whose first member is a poor shift, each
  // within the one bound: short series (never beyond the limit), 20 (just beyond), 10 and 1000 members,
  // and values far from 0 (where the shift's differences are exact and a float mean is not).
  for (const uint32_t members : {4u, 10u, 20u, 1000u})
    for (const auto data : {CorrelationCase::Data::pearson_shift, CorrelationCase::Data::pearson_shift_offset}) {
      const CorrelationCase c{{CorrelationMeasure::Pearson}, members, 0, 0, data};
      cases.push_back({"correlation_pearson", "CorrelationKernel", correlation_name(c), members < 1000,
                       CorrelationKernel::workgroup_size(c.params, members),
                       [c](Context& ctx, Check& check) { correlation(ctx, check, c); }});
    }
}

}  // namespace tfm::selftest
