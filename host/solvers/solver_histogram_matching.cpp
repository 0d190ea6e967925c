// The `histogram-matching` solver: both fields' histograms on the GPU, the quantile mapping
// T_o(v) = T_r(F_r^-1(F_o(v))) on the host (host/solvers/histogram_matching.h says what it can
// and cannot match). No least-squares objective, so --ridge and --smooth do not apply.
#include <chrono>

#include "tfmatch/model/cancellation.h"
#include "tfmatch/solvers/histogram_matching.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {
namespace {

class HistogramMatchingSolver final : public Solver {
 public:
  std::string_view name() const override { return "histogram-matching"; }
  std::string_view summary() const override {
    return "T_o = T_r(F_r^-1(F_o)): the reference TF at the same quantile (baseline; matches monotone increasing "
           "relations only)";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, false, false}; }
  std::vector<SolverOption> options() const override {
    return {SolverOption::integer("histogram-bins", 4096, 16, TFM_HIST_MAX_BINS,
                                  "bins of each field's histogram over its mapped range (quantile resolution)")};
  }

  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    SolverOutput out;
    const auto t0 = std::chrono::steady_clock::now();
    const FieldHistogramKernel kernel(p.ctx, uint32_t(args.integer("histogram-bins")));
    const FieldRange rr = mapping_range(p.ref_map), ro = mapping_range(p.opt_map);
    const FieldHistogram ref = kernel.run(p.ref, rr.lo, rr.hi);
    checkpoint("solve");
    const FieldHistogram opt = kernel.run(p.opt, ro.lo, ro.hi);
    out.phases.push_back({"histograms", ms_since(t0), -1.0});
    if (ref.finite() == 0 || opt.finite() == 0)
      throw std::runtime_error(std::string("histogram matching: the ") + (ref.finite() == 0 ? "reference" : "second") +
                               " field has no voxel with data");
    const auto t1 = std::chrono::steady_clock::now();
    out.tf = histogram_matching_tf(ref, opt, p.ref_tf, p.ref_map, p.opt_map);
    out.phases.push_back({"quantile mapping", ms_since(t1), -1.0});
    out.details["histogram_bins"] = uint64_t(kernel.bins());
    out.details["reference_below_above"] = std::to_string(ref.below) + " / " + std::to_string(ref.above);
    out.details["field_below_above"] = std::to_string(opt.below) + " / " + std::to_string(opt.above);
    return out;
  }
};

}  // namespace

std::unique_ptr<Solver> make_histogram_matching_solver() { return std::make_unique<HistogramMatchingSolver>(); }

}  // namespace tfm
