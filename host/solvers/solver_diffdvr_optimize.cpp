// The "diffdvr" solver: the projected-Adam loop over batches of cameras, its options.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>

#include "tfmatch/model/cameras.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/solvers/adam.h"
#include "tfmatch/solvers/solver_diffdvr.h"
#include "tfmatch/solvers/solver_normal_equations.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {
namespace {

// lambda (N-1) sum_j sum_c (T[j+1][c] - T[j][c])^2, about lambda * integral of |T'(t)|^2 dt, so a
// weight means the same for any N. Adds its gradient to `grad`; returns the penalty.
double add_smoothness(const std::vector<double>& x, double lambda, std::vector<double>& grad) {
  if (lambda == 0.0) return 0.0;
  const size_t n = x.size() / 4;
  const double scale = lambda * double(n - 1);
  double penalty = 0.0;
  for (size_t j = 0; j + 1 < n; ++j)
    for (size_t c = 0; c < 4; ++c) {
      const double d = x[4 * (j + 1) + c] - x[4 * j + c];
      penalty += scale * d * d;
      grad[4 * (j + 1) + c] += 2.0 * scale * d;
      grad[4 * j + c] -= 2.0 * scale * d;
    }
  return penalty;
}

}  // namespace

DiffDvrResult solve_diffdvr_gpu(VoxelProblem& p, const DiffDvrOptions& o) {
  if (o.iterations < 1 || o.views_per_iteration < 1)
    throw std::invalid_argument("solve_diffdvr_gpu: iterations and views per iteration must be >= 1");
  if (!(o.learning_rate > 0 && o.learning_rate <= 1))
    throw std::invalid_argument("solve_diffdvr_gpu: learning rate must be in (0, 1]");
  if (!(o.smooth >= 0 && o.smooth <= kMaxDiffDvrSmooth))
    throw std::invalid_argument("solve_diffdvr_gpu: smooth must be in [0, 1e9]");
  validate(o.render);
  DiffDvrResult out;
  TransferFunction tf = p.initial;
  if (o.start == DiffDvrStart::NormalEquations) {
    NormalEquationsGpuResult init = solve_normal_equations_gpu(p, o.normal_equations);
    for (PhaseTime& ph : init.phases) out.phases.push_back({"init: " + ph.name, ph.wall_ms, ph.gpu_ms});
    for (std::string& w : init.solve.warnings) out.warnings.push_back("init: " + w);
    tf = init.solve.tf;
  }
  const size_t n = tf.size();
  auto t0 = std::chrono::steady_clock::now();
  const VolumeGeometry geometry = VolumeGeometry::from(p.opt_volume.dims, p.opt_volume.spacing, o.render.z_scale);
  DiffDvrGradient gradient(p.ctx, p.ref, p.opt, geometry, p.ref_map, p.ref_tf_buffer, p.opt_map, o.render, o.loss);
  out.phases.push_back({"diffdvr setup", ms_since(t0), -1.0});

  std::vector<double> x(4 * n);
  for (size_t j = 0; j < n; ++j)
    for (size_t c = 0; c < 4; ++c) x[4 * j + c] = std::clamp(tf.rgba[j][c], 0.0, 1.0);
  AdamOptions adam_options;
  adam_options.learning_rate = o.learning_rate;
  Adam adam(x.size(), adam_options);
  RandomCameras random(o.seed, o.render.camera);
  const std::vector<OrbitCamera> fixed = fibonacci_cameras(o.views_per_iteration, o.render.camera);
  // The pool: random cameras drawn once, their reference images rendered once; each iteration
  // takes a seeded choice of them, so only the second field is rendered per iteration.
  const bool pooled = o.view_pool > 0 && !o.fibonacci;
  std::mt19937_64 choose(o.seed ^ 0x9E3779B97F4A7C15ull);
  std::vector<uint32_t> pool_order;
  if (pooled) {
    t0 = std::chrono::steady_clock::now();
    gradient.set_view_pool(random.next(std::max(o.view_pool, o.views_per_iteration)));
    pool_order.resize(gradient.pool_size());
    for (uint32_t i = 0; i < pool_order.size(); ++i) pool_order[i] = i;
    out.phases.push_back({"diffdvr reference pool", ms_since(t0), -1.0});
  }
  auto to_tf = [&] {
    for (size_t j = 0; j < n; ++j)
      for (size_t c = 0; c < 4; ++c) tf.rgba[j][c] = x[4 * j + c];
  };

  std::vector<double> curve;
  double forward_ms = 0, backward_ms = 0;
  bool timed = true;
  // The mean image loss on the fixed Fibonacci views: comparable between runs and seeds.
  // Eight views per submission, so that a stop (Ctrl-C, the viewer's) waits for eight, not all.
  auto fixed_view_loss = [&] {
    to_tf();
    double loss = 0.0, components = 0.0;
    for (size_t first = 0; first < fixed.size(); first += 8) {
      checkpoint("solve");
      const size_t count = std::min<size_t>(8, fixed.size() - first);
      const ImageLossGradient r = gradient.evaluate(tf, std::span<const OrbitCamera>(fixed).subspan(first, count));
      loss += r.loss;
      components += double(r.components);
    }
    return loss / components;
  };
  const double initial_fixed_loss = fixed_view_loss();
  Progress progress("diffdvr", o.iterations);
  t0 = std::chrono::steady_clock::now();
  for (uint32_t it = 0; it < o.iterations; ++it) {
    checkpoint("solve");
    to_tf();
    ImageLossGradient r;
    if (pooled) {
      // views_per_iteration distinct pool cameras: the first entries of a partial shuffle.
      for (uint32_t i = 0; i < o.views_per_iteration; ++i)
        std::swap(pool_order[i], pool_order[i + choose() % (pool_order.size() - i)]);
      r = gradient.evaluate_pooled(tf, std::span<const uint32_t>(pool_order.data(), o.views_per_iteration));
    } else {
      r = gradient.evaluate(tf, o.fibonacci ? fixed : random.next(o.views_per_iteration));
    }
    timed = timed && r.forward_gpu_ms >= 0;
    forward_ms += r.forward_gpu_ms;
    backward_ms += r.backward_gpu_ms;
    // The mean over components: its scale does not depend on the image size or view count.
    std::vector<double> g(r.gradient.size());
    for (size_t i = 0; i < g.size(); ++i) g[i] = r.gradient[i] / double(r.components);
    const double loss = r.loss / double(r.components) + add_smoothness(x, o.smooth, g);
    curve.push_back(loss);
    adam.step(x, g);
    char label[64];
    std::snprintf(label, sizeof label, "diffdvr: loss %.4g", loss);
    progress.set_label(label);
    progress.update(it + 1);
  }
  progress.finish();
  out.phases.push_back({"diffdvr iterations", ms_since(t0), timed ? forward_ms + backward_ms : -1.0});
  const double final_fixed_loss = fixed_view_loss();
  out.tf = tf;

  out.loss_curve = std::move(curve);
  out.fixed_view_loss_initial = initial_fixed_loss;
  out.fixed_view_loss_final = final_fixed_loss;
  out.fixed_views = uint32_t(fixed.size());
  out.views_per_group = gradient.views_per_group();
  if (timed) out.forward_gpu_ms = forward_ms, out.backward_gpu_ms = backward_ms;
  return out;
}

namespace {

class DiffDvrSolver final : public Solver {
 public:
  std::string_view name() const override { return "diffdvr"; }
  std::string_view summary() const override {
    return "image-based: projected Adam on the image loss over random views, gradients by DiffDVR's inversion "
           "(minutes on large fields)";
  }
  // --smooth is its own prior here (see below); --ridge does not apply.
  SolverConstraints constraints() const override { return {BoxHandling::Projected, false, true, true}; }
  bool image_based() const override { return true; }
  std::vector<SolverOption> options() const override {
    return {SolverOption::choice("loss", "l2", {"l2", "l1"}, "image loss over RGBA"),
            SolverOption::choice("optimizer", "adam", {"adam"}, "step rule"),
            SolverOption::number("lr", 0.02, {.min = 0.0, .max = 1.0, .min_open = true}, "Adam learning rate"),
            SolverOption::integer("iterations", 200, 1, 1000000, "iterations"),
            SolverOption::integer("views-per-iteration", 8, 1, 4096, "cameras per iteration"),
            SolverOption::integer("view-pool", 32, 0, 65536,
                                  "random cameras drawn once, reference images rendered once; each iteration "
                                  "takes views-per-iteration of them (0: new cameras every iteration)"),
            SolverOption::integer("image-size", 512, 1, 16384, "image width and height in pixels"),
            SolverOption::integer("seed", 1, 0, std::numeric_limits<uint64_t>::max(), "seed of the random cameras"),
            SolverOption::choice("cameras", "random", {"random", "fibonacci"},
                                 "new random views each iteration, or fixed Fibonacci-sphere views"),
            SolverOption::choice("init", "reference", {"reference", "normal-equations"}, "initial TF")};
  }

  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    DiffDvrOptions o;
    o.loss = args.text("loss") == "l1" ? ImageLoss::L1 : ImageLoss::L2;
    o.iterations = uint32_t(args.integer("iterations"));
    o.views_per_iteration = uint32_t(args.integer("views-per-iteration"));
    o.view_pool = uint32_t(args.integer("view-pool"));
    o.seed = args.integer("seed");
    o.fibonacci = args.text("cameras") == "fibonacci";
    o.start = args.text("init") == "normal-equations" ? DiffDvrStart::NormalEquations : DiffDvrStart::Reference;
    o.normal_equations = args.solve;
    o.learning_rate = args.number("lr");
    // The weight of (N-1) sum of squared TF differences, added to the mean image loss.
    o.smooth = args.solve.smooth;
    if (!(o.smooth >= 0 && o.smooth <= kMaxDiffDvrSmooth)) {
      std::ostringstream os;
      os << parameter("smooth") << " " << o.smooth << ": diffdvr takes a weight in [0, " << kMaxDiffDvrSmooth
         << "]; at " << kMaxDiffDvrSmooth << " the TF it tends to is already constant to ~1e-11";
      throw std::runtime_error(os.str());
    }
    o.render = args.render;
    o.render.width = o.render.height = uint32_t(args.integer("image-size"));
    const DiffDvrResult r = solve_diffdvr_gpu(p, o);

    SolverOutput out;
    out.tf = r.tf;
    out.phases = r.phases;
    out.warnings = r.warnings;
    Details& d = out.details;
    d["loss_curve"] = r.loss_curve;
    // The smoothness penalty is part of the curve, not of these image losses.
    Details fixed;
    fixed["initial"] = r.fixed_view_loss_initial;
    fixed["final"] = r.fixed_view_loss_final;
    fixed["views"] = r.fixed_views;
    d["fixed_view_loss"] = fixed;
    d["loss"] = image_loss_name(o.loss);
    d["iterations"] = o.iterations;
    d["views_per_iteration"] = o.views_per_iteration;
    d["view_pool"] = o.fibonacci ? 0u : o.view_pool;
    d["image_size"] = o.render.width;
    d["cameras"] = args.text("cameras");
    d["seed"] = o.seed;
    d["lr"] = o.learning_rate;
    d["init"] = args.text("init");
    d["smooth"] = o.smooth;
    d["views_per_group"] = r.views_per_group;
    if (r.forward_gpu_ms >= 0) {
      Details gpu_ms;
      gpu_ms["forward"] = r.forward_gpu_ms;
      gpu_ms["backward"] = r.backward_gpu_ms;
      d["gpu_ms"] = gpu_ms;
    }
    return out;
  }
};

}  // namespace

std::unique_ptr<Solver> make_diffdvr_solver() { return std::make_unique<DiffDvrSolver>(); }

}  // namespace tfm
