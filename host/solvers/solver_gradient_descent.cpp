// The `gradient-descent` solver: matrix-free projected gradient descent on the GPU, l2 or l1 voxel
// loss, Jacobi-scaled SGD or Adam, from x = 0 (so unreferenced entries stay 0, as in the other
// solvers). The learning rate follows a cosine schedule from --lr down to 1% of it at the last
// iteration, which lets the l1 iteration (a subgradient method) settle on its minimizer.
#include "tfmatch/solvers/solver_gradient_descent.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/gradient_descent.h"
#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/kernels/voxel_pair.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/solvers/box_qp.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {
namespace {

constexpr uint32_t kIterationsPerBatch = 32;
// Farther than this from the optimum (TF units; 2.5 of 255 colour levels) the solver warns.
constexpr double kDistanceWarning = 1e-2;

}  // namespace

GradientDescentResult solve_gradient_descent_gpu(VoxelProblem& p, const GradientDescentOptions& o) {
  if (!(o.lr > 0.0) || !std::isfinite(o.lr)) throw std::invalid_argument("solve_gradient_descent_gpu: lr must be > 0");
  if (o.iterations < 1) throw std::invalid_argument("solve_gradient_descent_gpu: iterations must be >= 1");
  Context& ctx = p.ctx;
  const uint32_t n = p.opt_map.tf_size;

  GradientDescentResult out;
  auto t0 = std::chrono::steady_clock::now();
  JacobiSetup js = jacobi_setup(p, o.regularization);
  Buffer inv_diag = make_buffer<float>(ctx, js.inv_diag, "GD inverse diagonal");
  Buffer x(ctx, uint64_t(n) * 16, MemoryUsage::Device, "GD x");
  Buffer m(ctx, uint64_t(n) * 16, MemoryUsage::Device, "GD Adam m");
  Buffer v(ctx, uint64_t(n) * 16, MemoryUsage::Device, "GD Adam v");
  Buffer gradient(ctx, uint64_t(n) * 16, MemoryUsage::Device, "GD gradient");
  Buffer accum(ctx, gd_accumulator_bytes(n), MemoryUsage::Device, "GD accumulators");
  fill(ctx, x, 0u);
  fill(ctx, m, 0u);
  fill(ctx, v, 0u);
  const GdGradientKernel grad_kernel(ctx, n, o.l1);
  const GdUpdateKernel update_kernel(ctx);
  const GdUpdateBuffers buffers{&accum, &x, &m, &v, &inv_diag, &gradient};
  gpu::GdUpdatePush base = gd_push(o, n, js.eq.voxels, js.reg);
  out.phases.push_back({"setup", ms_since(t0), js.gpu_ms});

  t0 = std::chrono::steady_clock::now();
  double gpu_ms = 0.0;
  Progress progress("gradient-descent", o.iterations);  // thousands of iterations on large fields take minutes
  for (uint32_t done = 0; done < o.iterations;) {
    checkpoint("solve");
    const uint32_t count = std::min(kIterationsPerBatch, o.iterations - done);
    CommandBatch batch(ctx);
    const uint32_t a = batch.timestamp();
    for (uint32_t k = 0; k < count; ++k) {
      const uint32_t t = done + k + 1;
      batch.fill(accum, 0u);
      // Zeroed accumulators and the previous step's x are visible before the gradient pass.
      batch.barrier();
      grad_kernel.record(batch, p.ref, p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer, x, accum);  // ends with barrier
      update_kernel.record(batch, gd_step_push(base, o, t), buffers);
      // The new x is written before the next gradient pass reads it.
      batch.barrier();
    }
    const uint32_t b = batch.timestamp();
    batch.submit_and_wait();
    gpu_ms = batch.elapsed_ms(a, b) >= 0 ? gpu_ms + batch.elapsed_ms(a, b) : -1.0;
    done += count;
    progress.update(done);
  }
  progress.finish();
  out.phases.push_back({"iterate", ms_since(t0), ctx.timestamps_supported() ? gpu_ms : -1.0});

  std::vector<float> xs(size_t(n) * 4);
  readback(ctx, x, xs.data(), xs.size() * sizeof(float));
  out.tf = tf_from_floats(xs);
  std::vector<uint32_t> words(gd_accumulator_bytes(n) / 4);
  readback(ctx, accum, words.data(), words.size() * 4);
  const auto loss_words = words.begin() + TFM_FIXED_SLOT_WORDS * TFM_GD_LOSS_SLOT(n);
  std::vector<double> loss = decode_fixed_point(std::vector<uint32_t>(loss_words, words.end()));
  double total = 0.0;
  for (double l : loss) total += l;
  // Mean over voxels and RGBA of e^2 (l2) or |e| (l1) at the last gradient evaluation.
  out.last_loss = total / (4.0 * double(js.eq.voxels));
  if (!o.l1) {
    const BoxQpResult optimum = solve_box_constrained(js.eq, o.regularization);
    double worst = 0.0;
    for (uint32_t j = 0; j < n; ++j)
      for (int c = 0; c < 4; ++c) worst = std::max(worst, std::abs(double(xs[4 * j + c]) - optimum.x(j, c)));
    out.distance_to_optimum = worst;
  }
  return out;
}

double gd_learning_rate(const GradientDescentOptions& o, uint32_t t) {
  const double progress = o.iterations > 1 ? double(t - 1) / double(o.iterations - 1) : 0.0;
  return o.lr * (o.final_lr_fraction + (1.0 - o.final_lr_fraction) * 0.5 * (1.0 + std::cos(std::numbers::pi * progress)));
}

gpu::GdUpdatePush gd_push(const GradientDescentOptions& o, uint32_t tf_size, uint64_t voxels, const Regularization& reg) {
  gpu::GdUpdatePush push{};
  push.tf_size = tf_size;
  push.optimizer = o.adam ? TFM_GD_OPTIMIZER_ADAM : TFM_GD_OPTIMIZER_SGD;
  // Loss = mean over voxels and RGBA of e^2 (or |e|) + x^T R x / (4 V).
  const double per_component = 1.0 / (4.0 * double(std::max<uint64_t>(voxels, 1)));
  push.data_scale = float((o.l1 ? 1.0 : 2.0) * per_component);
  push.reg_scale = float(2.0 * per_component);
  push.ridge_weight = float(reg.ridge);
  push.smooth_weight = float(reg.smooth);
  push.beta1 = float(o.beta1);
  push.beta2 = float(o.beta2);
  push.epsilon = float(o.epsilon);
  return push;
}

gpu::GdUpdatePush gd_step_push(const gpu::GdUpdatePush& base, const GradientDescentOptions& o, uint32_t t) {
  gpu::GdUpdatePush push = base;
  push.lr = float(gd_learning_rate(o, t));
  push.bias1 = float(1.0 / (1.0 - std::pow(o.beta1, double(t))));
  push.bias2 = float(1.0 / (1.0 - std::pow(o.beta2, double(t))));
  return push;
}

namespace {

class GradientDescentSolver final : public Solver {
 public:
  std::string_view name() const override { return "gradient-descent"; }
  std::string_view summary() const override {
    return "matrix-free projected gradient descent on the GPU, l2 or l1 voxel loss, Adam or Jacobi-scaled SGD";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Projected, true, true}; }
  std::vector<SolverOption> options() const override {
    SolverOption lr = SolverOption::number("lr", 0.0, {.min = 0.0, .min_open = true},
                                           "initial step (adam: TF units; sgd: fraction of a diagonal Newton "
                                           "step), cosine schedule down to 1% of it");
    lr.default_value = std::monostate{};  // depends on --optimizer
    lr.default_help = "0.02 with adam, 1 with sgd";
    return {SolverOption::choice("loss", "l2", {"l2", "l1"}, "voxel loss: least squares or least absolute deviations"),
            SolverOption::choice("optimizer", "adam", {"adam", "sgd"}, "step rule"),
            lr,
            SolverOption::integer("iterations", 300, 1, 1000000000, "iterations")};
  }

  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    GradientDescentOptions o;
    o.l1 = args.text("loss") == "l1";
    o.adam = args.text("optimizer") == "adam";
    o.lr = args.has("lr") ? args.number("lr") : (o.adam ? 0.02 : 1.0);
    o.iterations = uint32_t(args.integer("iterations"));
    o.regularization = args.solve;
    const GradientDescentResult r = solve_gradient_descent_gpu(p, o);
    SolverOutput out;
    out.tf = r.tf;
    out.phases = r.phases;
    out.details["box"] = "projected";  // every iterate is projected to [0,1]
    out.details["iterations"] = o.iterations;
    out.details["loss"] = o.l1 ? "l1" : "l2";
    out.details["optimizer"] = o.adam ? "adam" : "sgd";
    out.details["lr"] = o.lr;
    out.details["last_loss"] = r.last_loss;
    if (r.distance_to_optimum >= 0.0) out.details["distance_to_optimum"] = r.distance_to_optimum;
    out.details["ridge"] = args.solve.ridge;
    out.details["smooth"] = args.solve.smooth;
    if (r.distance_to_optimum > kDistanceWarning) {
      std::ostringstream os;
      os << "gradient descent ended after " << parameter("iterations") << " " << o.iterations
         << " with TF entries up to " << std::setprecision(2) << r.distance_to_optimum
         << " away from the exact minimizer of the same loss in [0,1]";
      if (args.solve.smooth > 0.0) os << " (" << parameter("smooth") << " makes the problem stiff for gradient steps)";
      os << "; more " << parameter("iterations") << " or another " << parameter("lr") << " may get closer, and "
         << parameter("solver") << " qp solves it exactly";
      out.warnings.push_back(os.str());
    }
    return out;
  }
};

}  // namespace

std::unique_ptr<Solver> make_gradient_descent_solver() { return std::make_unique<GradientDescentSolver>(); }

}  // namespace tfm
