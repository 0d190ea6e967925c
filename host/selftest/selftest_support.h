// Internals of the self-test (host/selftest/selftest.h): the comparison record every case fills,
// the case table, and the deterministic test data the cases share.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "tfmatch/engine/buffer.h"
#include "tfmatch/engine/context.h"
#include "tfmatch/engine/device_field.h"
#include "tfmatch/kernels/correlation.h"
#include "tfmatch/kernels/reduction.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/transfer_function.h"

namespace tfm::selftest {

// What one case compared: the element nearest to (or furthest past) its bound, the first element
// past its bound, or why the case could not run on this device.
class Check {
 public:
  explicit Check(double perturbation) : perturbation_(perturbation) {}

  // |device - reference| <= bound. `what` and `index` name the element in a failure message.
  // A NaN on either side fails.
  void near(const char* what, uint64_t index, double device, double reference, double bound);
  void equal(const char* what, uint64_t index, double device, double reference) {
    near(what, index, device, reference, 0.0);
  }
  // A precondition of the case itself (the scene must exercise what it claims to).
  void require(bool ok, const std::string& message);
  // The device lacks what the case needs: `reason` reads "needs ...".
  void skip(const std::string& reason) { skipped_ = reason; }

  bool failed() const { return !failure_.empty(); }
  const std::string& failure() const { return failure_; }
  const std::string& skipped() const { return skipped_; }
  double worst_error() const { return worst_error_; }
  double worst_bound() const { return worst_bound_; }
  uint64_t compared() const { return compared_; }

 private:
  double perturbation_;
  bool perturbed_ = false;
  double worst_ratio_ = -1.0, worst_error_ = 0.0, worst_bound_ = 0.0;
  uint64_t compared_ = 0;
  std::string failure_, skipped_;
};

// One case of the table. `run` builds its data, runs the kernel and compares through `check`;
// exceptions fail the case.
// The workgroup shape of a kernel: Vulkan guarantees only 128 invocations (and 128 along x).
struct Workgroup {
  Workgroup(uint32_t x_, uint32_t y_ = 1) : x(x_), y(y_) {}  // NOLINT: a bare size reads as 1-D
  uint32_t x, y;
};

struct CaseSpec {
  std::string kernel;   // shader name
  std::string wrapper;  // class of kernels/ that drives it
  std::string name;
  bool quick = true;    // part of --quick
  Workgroup workgroup;  // checked against the device's limits before the case runs
  std::function<void(Context&, Check&)> run;
  // Storage-buffer descriptors the kernel binds (an array binding counts each element); Vulkan
  // guarantees only 4 per stage.
  uint32_t storage_buffers = 6;
};
using CaseList = std::vector<CaseSpec>;

// The cases of each group of kernels, appended in report order.
void add_voxel_cases(CaseList& cases);   // assemble_normal_equations, voxel_loss, residual_map
void add_sparse_cases(CaseList& cases);  // sparse_prepare, sparse_gather, sparse_scatter, cgls_vectors
void add_gd_cases(CaseList& cases);      // gd_gradient, gd_update
void add_irls_cases(CaseList& cases);    // irls_assemble
void add_render_cases(CaseList& cases);  // render_image, diffdvr_forward, visibility_weights, diffdvr_backward
void add_correlation_cases(CaseList& cases);  // correlation_pearson, _spearman, _kendall, _mi_binned, _mi_kraskov
void add_device_cases(CaseList& cases);  // loop_probe

// ---- test data (fixed seeds) ----------------------------------------------------------------

// A reference field on [0, 1] and a second field on `opt_range`, both reaching 10% past their
// ranges (clamped), every 7th second-field value exactly on one of the `opt_tf_size` TF nodes,
// NaN at every 11th reference voxel (from 5) and every 13th second-field voxel (from 6).
struct FieldPair {
  std::vector<float> ref, opt;
};
FieldPair random_pair(size_t voxels, uint32_t seed, const FieldRange& opt_range, uint32_t opt_tf_size);

// The inputs of a case of the kernels that evaluate the residual at a TF (gd_gradient,
// irls_assemble): random_pair(voxels, seed + voxels) with both fields on [0, 1] and N optimized
// entries, a reference TF of 11 entries in [-0.1, 1.1] (seed + 1: b is clamped), their mappings,
// and the fields (split into chunks of chunk_voxels, 0: whole) and the TF on the device.
struct ResidualCaseInputs {
  ResidualCaseInputs(Context& ctx, size_t voxels, uint32_t seed, uint32_t n, uint64_t chunk_voxels);
  FieldPair pair;
  TransferFunction ref_tf;
  std::vector<float> ref_tf_floats;
  FieldMapping ref_map, opt_map;
  DeviceField ref, opt;
  Buffer tf;
};

// N entries with every component uniform in [lo, hi].
TransferFunction random_tf(uint32_t n, uint32_t seed, double lo = 0.0, double hi = 1.0);
std::vector<float> random_floats(size_t count, uint32_t seed, float lo, float hi);

// The TF at voxel value v through `map` as the kernels compute it (float TF entries and the
// bit-identical float coordinate, interpolated in double), clamped to [0, 1]; false for NaN.
bool classify(const std::vector<float>& tf_floats, const FieldMapping& map, float v, double out[4]);

// A member-major ensemble (kernels/correlation.h) for the correlation kernels' checks. Every value
// is a multiple of 2^-10 in [0, 4], and members 0 and 1 of every series are 0 and 4 (or 4 and 0),
// so each series spans exactly 4 and every float operation the kernels do on member values
// (differences, bins, distances, comparisons) is exact, as in the double references. Voxel 0 is
// the reference series itself; voxel v depends on it with a strength cos(0.7 v) (from -1 to 1)
// plus uniform noise; every 3rd voxel is rounded to multiples of 1/4 (many ties, repeated
// points); voxel 5 has a NaN member and voxel 7 is constant (where the grid has them).
struct CorrelationEnsemble {
  uint32_t members = 0;
  uint64_t voxels = 0;
  std::vector<float> values;  // values[m * voxels + v]
  EnsembleView view() const { return {values.data(), members, voxels}; }
  std::vector<float> reference() const { return ensemble_series(view(), 0); }
};
CorrelationEnsemble correlation_test_ensemble(uint32_t members, uint64_t voxels, uint32_t seed);
// Every series spans [0, 3] and its other values lie within 4 ulp of the edges of 10 equal bins
// (k * 3 / 10 in float): where a binning by division and one by products part ways.
CorrelationEnsemble bin_edge_ensemble(uint32_t members, uint64_t voxels);
// Pearson's shift (shaders/correlation_pearson.comp): voxel 0 holds the reference series
// (reference()); every other voxel has member 0 placed so that M (mean - y0)^2 is a chosen
// multiple q of the series' squared deviations, q from 0 to nearly M - 1 (member 0 the only
// outlier) and either side of TFM_CORR_PEARSON_SHIFT_LIMIT, above and below the other members,
// which are `offset` plus noise correlated with the reference. The reference's member 0 is an
// outlier too, so r nears +-1 at the large q, where a one-pass sum would cancel most.
CorrelationEnsemble pearson_shift_ensemble(uint32_t members, float offset, uint32_t seed);
// Series of other spreads than the reference's (voxel 0: multiples of 2^-10 in [0, 4], spanning
// it): voxel 1 independent of it on [0, 4000] (multiples of 1/4), voxel 2 1000 times it, voxel 3
// independent on [0, 4 / 1024]. Every difference stays exact in float. Where y spreads far wider
// than x, the k nearest neighbours in the max norm are decided by y, and a Kraskov search walks
// past nearly every member.
CorrelationEnsemble spread_ensemble(uint32_t members, uint32_t seed);

// The words of a device buffer.
std::vector<uint32_t> read_words(Context& ctx, const Buffer& buffer, size_t words);

// "needs N KiB of workgroup shared memory (device: M KiB)".
std::string needs_shared_memory(const Context& ctx, uint64_t bytes);
bool fits_shared_memory(const Context& ctx, uint64_t bytes);

// Every forced path of the voxel-reducing kernels: 3 modes x 2 atomic widths, less private
// histograms with 32-bit atomics (not a path).
std::vector<ReductionOptions> reduction_paths();
// ", runs, shared memory, 64-bit atomics" (empty for the automatic choice).
std::string reduction_name(const ReductionOptions& options);
// Why the device cannot run `options` for a kernel of `tf_size` entries whose shared
// accumulators take `shared_bytes` and whose private histograms hold up to `private_max_bins`
// entries, or "" when it can.
std::string reduction_unavailable(const Context& ctx, const ReductionOptions& options, uint32_t tf_size,
                                  uint64_t shared_bytes, uint32_t private_max_bins = kPrivateMaxBins);

// Case names: "1 voxel", "257 voxels", ...
std::string voxels_name(size_t voxels);

}  // namespace tfm::selftest
