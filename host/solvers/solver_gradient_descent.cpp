// The `gradient-descent` solver: matrix-free projected gradient descent on the GPU, l2 or l1 voxel
// loss, Jacobi-scaled SGD or Adam, from x = 0 (so unreferenced entries stay 0, as in the other
// solvers). The learning rate follows a cosine schedule from --lr down to 1% of it at the last
// iteration, which lets the l1 iteration (a subgradient method) settle on its minimizer.
#include "solver_gradient_descent.h"
#include "solver_registry.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "commands.h"
#include "gradient_descent.h"
#include "solver_support.h"
#include "sparse_ops.h"

namespace tfm {
namespace {

constexpr uint32_t kIterationsPerBatch = 32;

SolverOutput solve_with_gradient_descent(VoxelProblem& p, const SolverSettings& settings) {
  const GdOptions o = gd_options(settings);
  Context& ctx = p.ctx;
  const uint32_t n = p.opt_map.tf_size;

  SolverOutput out;
  auto t0 = std::chrono::steady_clock::now();
  JacobiSetup js = jacobi_setup(p, settings);
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
  for (uint32_t done = 0; done < o.iterations;) {
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
  }
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
  out.details["box"] = "projected";  // every iterate is projected to [0,1]
  out.details["iterations"] = o.iterations;
  out.details["loss"] = o.l1 ? "l1" : "l2";
  out.details["optimizer"] = o.adam ? "adam" : "sgd";
  out.details["lr"] = o.lr;
  // Mean over voxels and RGBA of e^2 (l2) or |e| (l1) at the last gradient evaluation.
  out.details["last_loss"] = total / (4.0 * double(js.eq.voxels));
  out.details["ridge"] = settings.solve.ridge;
  out.details["smooth"] = settings.solve.smooth;
  return out;
}


}  // namespace

GdOptions gd_options(const SolverSettings& settings) {
  GdOptions o;
  const std::string loss = settings.text("loss", "l2");
  if (loss != "l2" && loss != "l1") throw std::runtime_error("--loss: expected l2 or l1, got '" + loss + "'");
  const std::string optimizer = settings.text("optimizer", "adam");
  if (optimizer != "adam" && optimizer != "sgd")
    throw std::runtime_error("--optimizer: expected adam or sgd, got '" + optimizer + "'");
  o.l1 = loss == "l1";
  o.adam = optimizer == "adam";
  o.lr = settings.number("lr", o.adam ? 0.02 : 1.0);
  if (!(o.lr > 0.0) || !std::isfinite(o.lr)) throw std::runtime_error("--lr: expected a positive number");
  o.iterations = positive_integer(settings, "iterations", 300);
  return o;
}

double gd_learning_rate(const GdOptions& o, uint32_t t) {
  const double progress = o.iterations > 1 ? double(t - 1) / double(o.iterations - 1) : 0.0;
  return o.lr * (o.final_lr_fraction + (1.0 - o.final_lr_fraction) * 0.5 * (1.0 + std::cos(std::numbers::pi * progress)));
}

gpu::GdUpdatePush gd_push(const GdOptions& o, uint32_t tf_size, uint64_t voxels, const Regularization& reg) {
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

gpu::GdUpdatePush gd_step_push(const gpu::GdUpdatePush& base, const GdOptions& o, uint32_t t) {
  gpu::GdUpdatePush push = base;
  push.lr = float(gd_learning_rate(o, t));
  push.bias1 = float(1.0 / (1.0 - std::pow(o.beta1, double(t))));
  push.bias2 = float(1.0 / (1.0 - std::pow(o.beta2, double(t))));
  return push;
}

SolverOutput run_gradient_descent_solver(VoxelProblem& p, const SolverSettings& s) { return solve_with_gradient_descent(p, s); }

}  // namespace tfm
