// The `irls` solver: least absolute deviations (gradient-descent's l1 objective) by iteratively
// reweighted least squares. Each pass evaluates the l1 loss at x and assembles, for each
// channel, the normal equations weighted by w = delta / max(|e|, delta): minimizing
// sum w e^2 + 2 delta x^T R x over the box is the majorize-minimize step of the Huber loss of
// threshold delta (|e| <= e^2 / (2 max(|e_k|, delta)) + const at the current residual e_k), so
// the Huber objective never increases at a fixed delta. delta shrinks from 1/shrink to its floor
// (continuation), then the passes go on, over-relaxed (IrlsOptions::overrelax_max), until one
// gains less than the tolerance.
#include "tfmatch/solvers/solver_irls.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/irls.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/solvers/box_qp.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {
namespace {

// (sum_c x_c^T R x_c) for R = ridge I + smooth D^T D.
double penalty(const std::vector<float>& x, uint32_t n, const Regularization& reg) {
  double total = 0.0;
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t c = 0; c < 4; ++c) {
      const double v = x[4 * j + c];
      total += reg.ridge * v * v;
      if (j + 1 < n) {
        const double d = double(x[4 * (j + 1) + c]) - v;
        total += reg.smooth * d * d;
      }
    }
  return total;
}

}  // namespace

IrlsResult solve_irls_gpu(VoxelProblem& p, const IrlsOptions& o) {
  if (!(o.delta > 0.0 && o.delta < 1.0)) throw std::invalid_argument("solve_irls_gpu: delta must be in (0, 1)");
  if (!(o.shrink > 1.0) || !std::isfinite(o.shrink)) throw std::invalid_argument("solve_irls_gpu: shrink must be > 1");
  if (!(o.tolerance > 0.0 && o.tolerance < 1.0)) throw std::invalid_argument("solve_irls_gpu: tolerance must be in (0, 1)");
  if (o.max_iterations < 1) throw std::invalid_argument("solve_irls_gpu: max_iterations must be >= 1");
  if (!(o.overrelax_max >= 1.0 && o.overrelax_growth >= 1.0) || !std::isfinite(o.overrelax_max * o.overrelax_growth))
    throw std::invalid_argument("solve_irls_gpu: overrelax_max and overrelax_growth must be >= 1");
  Context& ctx = p.ctx;
  const uint32_t n = p.opt_map.tf_size;
  IrlsResult out;

  // The start: the box-constrained least-squares fit of the problem's own (unweighted) system,
  // which run_optimize assembles anyway for its losses.
  const NormalEquations& eq = assembled_system(p, &out.phases);
  auto t0 = std::chrono::steady_clock::now();
  const Regularization reg = absolute_regularization(eq, o.regularization);
  const BoxQpResult start = solve_box_constrained(eq, o.regularization);
  using Iterate = Eigen::Matrix<double, Eigen::Dynamic, 4>;
  Iterate x = start.x;
  Iterate best_step;   // the plain step from the best iterate: where the passes go on after a rejection
  double beta = 1.0;   // over-relaxation of the next step
  bool relaxed = false;  // the iterate of this pass is an over-relaxed step
  const IrlsKernel kernel(ctx, n);
  Buffer state(ctx, irls_state_bytes(n), MemoryUsage::Device, "IRLS state");
  Buffer accum(ctx, irls_accumulator_bytes(n), MemoryUsage::Device, "IRLS accumulators");
  out.phases.push_back({"setup", ms_since(t0), -1.0});

  t0 = std::chrono::steady_clock::now();
  double gpu_ms = 0.0;
  double delta = std::max(o.delta, 1.0 / o.shrink);
  double best = std::numeric_limits<double>::infinity();
  bool previous_at_floor = false;
  std::vector<float> values(size_t(n + 1) * 4), best_values;
  std::vector<uint32_t> words(irls_accumulator_bytes(n) / 4);
  Progress progress("irls", o.max_iterations);
  for (uint32_t pass = 1;; ++pass) {
    checkpoint("solve");
    for (uint32_t j = 0; j < n; ++j)
      for (uint32_t c = 0; c < 4; ++c) values[4 * j + c] = float(std::clamp(x(j, c), 0.0, 1.0));
    for (uint32_t c = 0; c < 4; ++c) values[4 * n + c] = float(delta);
    upload(ctx, state, values.data(), values.size() * sizeof(float));
    CommandBatch batch(ctx);
    const uint32_t a = batch.timestamp();
    batch.fill(accum, 0u);
    // The zeroed accumulators are visible to the pass.
    batch.barrier();
    kernel.record(batch, p.ref, p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer, state, accum);
    const uint32_t b = batch.timestamp();
    batch.submit_and_wait();
    gpu_ms = gpu_ms >= 0 && batch.elapsed_ms(a, b) >= 0 ? gpu_ms + batch.elapsed_ms(a, b) : -1.0;
    readback(ctx, accum, words.data(), words.size() * 4);
    const IrlsSums sums = IrlsSums::from_words(n, words);

    // The objective at the x this pass evaluated (the floats the device read).
    const double f = (sums.l1[0] + sums.l1[1] + sums.l1[2] + sums.l1[3] + penalty(values, n, reg)) /
                     (4.0 * double(eq.voxels));
    out.history.push_back(f);
    out.iterations = pass;
    progress.update(pass);
    const bool at_floor = delta <= o.delta;
    const double gain = best - f;
    const bool lowered = f < best;
    if (lowered) {
      best = f;
      best_values.assign(values.begin(), values.begin() + 4 * n);
    }
    // (A rejected over-relaxed step says nothing about convergence.)
    if ((lowered || !relaxed) && previous_at_floor && at_floor && gain <= o.tolerance * f) {
      out.converged = true;
      break;
    }
    if (pass == o.max_iterations) break;
    if (!lowered && relaxed) {
      // An over-relaxed step that did not lower the objective: drop it and go on from the plain
      // step of the best iterate. (A plain step is kept as before: it lowers the Huber loss of
      // its threshold, if not always the l1 loss.)
      ++out.rejected;
      x = best_step;
      relaxed = false;
      beta = 1.0;
      delta = std::max(o.delta, delta / o.shrink);
      continue;
    }
    previous_at_floor = at_floor;

    // The weighted, regularized system of each channel, solved exactly in the box from x.
    const Iterate from = x;
    for (uint32_t c = 0; c < 4; ++c) {
      NormalEquations weighted(n);
      weighted.diag = sums.diag[c];
      weighted.off = sums.off[c];
      const Tridiagonal h = regularized_matrix(weighted, {2.0 * delta * reg.ridge, 2.0 * delta * reg.smooth});
      const Eigen::VectorXd rhs = Eigen::Map<const Eigen::VectorXd>(sums.rhs[c].data(), n);
      Eigen::VectorXd xc = x.col(c);
      solve_box_qp(h, rhs, xc);
      x.col(c) = xc;
    }
    if (lowered) best_step = x;
    // Over-relaxed only from a best iterate at the final threshold: during the continuation each
    // pass's system is another Huber loss's, and a longer step towards one overshoots the next.
    relaxed = lowered && at_floor && beta > 1.0;
    if (relaxed) x = (from + beta * (x - from)).cwiseMax(0.0).cwiseMin(1.0);
    if (lowered && at_floor) beta = std::min(beta * o.overrelax_growth, o.overrelax_max);
    delta = std::max(o.delta, delta / o.shrink);
  }
  progress.finish();
  out.phases.push_back({"iterate", ms_since(t0), ctx.timestamps_supported() ? gpu_ms : -1.0});
  out.tf = tf_from_floats(best_values);
  out.loss = best;
  return out;
}

namespace {

class IrlsSolver final : public Solver {
 public:
  std::string_view name() const override { return "irls"; }
  std::string_view summary() const override {
    return "least absolute deviations (a robust fit: real changes do not bend the TF) by iteratively reweighted "
           "least squares: GPU passes, exact box-constrained solves";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Enforced, true, true}; }
  std::vector<SolverOption> options() const override {
    return {SolverOption::number("delta", 1e-4, {.min = 0.0, .max = 1.0, .min_open = true, .max_open = true},
                                 "residuals below this (colour units) weigh as this: the Huber threshold, the fit "
                                 "within voxels x delta / 2 of the l1 minimum"),
            SolverOption::number("tolerance", 1e-5, {.min = 0.0, .max = 1.0, .min_open = true, .max_open = true},
                                 "stop once a pass at the final threshold lowers the objective by less than this "
                                 "fraction"),
            SolverOption::integer("max-iterations", 100, 1, 1000000, "passes over the voxels at most")};
  }

  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    IrlsOptions o;
    o.delta = args.number("delta");
    o.tolerance = args.number("tolerance");
    o.max_iterations = uint32_t(args.integer("max-iterations"));
    o.regularization = args.solve;
    const IrlsResult r = solve_irls_gpu(p, o);
    SolverOutput out;
    out.tf = r.tf;
    out.phases = r.phases;
    if (!r.converged)
      out.warnings.push_back("irls: stopped after " + std::to_string(r.iterations) +
                             " passes before the objective settled (raise --max-iterations)");
    out.details["box"] = "enforced";  // every pass solves its system in the box exactly
    out.details["loss"] = "l1";
    out.details["iterations"] = r.iterations;
    out.details["rejected_steps"] = r.rejected;
    out.details["converged"] = r.converged;
    out.details["delta"] = o.delta;
    out.details["last_loss"] = r.loss;
    out.details["objective_per_pass"] = DetailValue::Numbers(r.history);
    out.details["ridge"] = args.solve.ridge;
    out.details["smooth"] = args.solve.smooth;
    return out;
  }
};

}  // namespace

std::unique_ptr<Solver> make_irls_solver() { return std::make_unique<IrlsSolver>(); }

}  // namespace tfm
