// The "diffdvr" solver: options, the projected-Adam loop over batches of cameras, registration.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "adam.h"
#include "solver_registry.h"
#include "cameras.h"
#include "progress.h"
#include "solver_diffdvr.h"

namespace tfm {
namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

uint32_t integer_flag(const SolverSettings& s, const std::string& name, uint32_t fallback, uint32_t lo, uint32_t hi) {
  const double v = s.number(name, fallback);
  if (!(v >= lo && v <= hi) || v != std::floor(v))
    throw std::runtime_error("--" + name + ": expected an integer in [" + std::to_string(lo) + ", " +
                             std::to_string(hi) + "], got '" + s.text(name, "") + "'");
  return uint32_t(v);
}

uint64_t seed_flag(const SolverSettings& s) {
  const std::string text = s.text("seed", "1");
  try {
    size_t used = 0;
    const unsigned long long v = std::stoull(text, &used);
    if (used == text.size() && text.find('-') == std::string::npos) return v;
  } catch (const std::exception&) {
  }
  throw std::runtime_error("--seed: expected a non-negative integer below 2^64, got '" + text + "'");
}

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

DiffDvrOptions DiffDvrOptions::from(const SolverSettings& s) {
  DiffDvrOptions o;
  o.loss = parse_image_loss(s.text("loss", "l2"));
  if (s.text("optimizer", "adam") != "adam")
    throw std::runtime_error("--optimizer: diffdvr supports adam only, got '" + s.text("optimizer", "") + "'");
  o.iterations = integer_flag(s, "iterations", o.iterations, 1, 1000000);
  o.views_per_iteration = integer_flag(s, "views-per-iteration", o.views_per_iteration, 1, 4096);
  o.image_size = integer_flag(s, "image-size", o.image_size, 1, 16384);
  o.seed = seed_flag(s);
  const std::string cameras = s.text("cameras", "random");
  if (cameras != "random" && cameras != "fibonacci")
    throw std::runtime_error("--cameras: expected random or fibonacci, got '" + cameras + "'");
  o.fibonacci = cameras == "fibonacci";
  o.init = s.text("init", "reference");
  if (o.init != "reference" && o.init != "normal-equations")
    throw std::runtime_error("--init: expected reference or normal-equations, got '" + o.init + "'");
  o.learning_rate = s.number("lr", o.learning_rate);
  if (!(o.learning_rate > 0 && o.learning_rate <= 1))
    throw std::runtime_error("--lr: expected a learning rate in (0, 1], got '" + s.text("lr", "") + "'");
  o.smooth = s.solve.smooth;
  if (!(o.smooth >= 0) || !std::isfinite(o.smooth)) throw std::runtime_error("--smooth: expected a weight >= 0");
  o.render = s.render;
  o.render.width = o.render.height = o.image_size;
  validate(o.render);
  return o;
}

SolverOutput solve_with_diffdvr(VoxelProblem& p, const SolverSettings& settings) {
  const DiffDvrOptions o = DiffDvrOptions::from(settings);
  SolverOutput out;
  TransferFunction tf = p.initial;
  if (o.init == "normal-equations") {
    SolverOutput init = solver_registry().at("normal-equations")(p, settings);
    for (PhaseTime& ph : init.phases) out.phases.push_back({"init: " + ph.name, ph.wall_ms, ph.gpu_ms});
    for (std::string& w : init.warnings) out.warnings.push_back("init: " + w);
    tf = init.tf;
  }
  const size_t n = tf.size();
  auto t0 = std::chrono::steady_clock::now();
  const VolumeGeometry geometry = VolumeGeometry::from(p.opt_volume.dims, p.opt_volume.spacing);
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
  auto to_tf = [&] {
    for (size_t j = 0; j < n; ++j)
      for (size_t c = 0; c < 4; ++c) tf.rgba[j][c] = x[4 * j + c];
  };

  std::vector<double> curve;
  double forward_ms = 0, backward_ms = 0;
  bool timed = true;
  // The mean image loss on the fixed Fibonacci views: comparable between runs and seeds.
  auto fixed_view_loss = [&] {
    to_tf();
    const ImageLossGradient r = gradient.evaluate(tf, fixed);
    return r.loss / double(r.components);
  };
  const double initial_fixed_loss = fixed_view_loss();
  Progress progress("diffdvr", o.iterations);
  t0 = std::chrono::steady_clock::now();
  for (uint32_t it = 0; it < o.iterations; ++it) {
    const std::vector<OrbitCamera> cameras = o.fibonacci ? fixed : random.next(o.views_per_iteration);
    to_tf();
    const ImageLossGradient r = gradient.evaluate(tf, cameras);
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

  nlohmann::json& d = out.details;
  d["loss_curve"] = curve;
  // The smoothness penalty is part of the curve, not of these image losses.
  d["fixed_view_loss"] = {{"initial", initial_fixed_loss}, {"final", final_fixed_loss}, {"views", fixed.size()}};
  d["loss"] = image_loss_name(o.loss);
  d["iterations"] = o.iterations;
  d["views_per_iteration"] = o.views_per_iteration;
  d["image_size"] = o.image_size;
  d["cameras"] = o.fibonacci ? "fibonacci" : "random";
  d["seed"] = o.seed;
  d["lr"] = o.learning_rate;
  d["init"] = o.init;
  d["smooth"] = o.smooth;
  d["views_per_group"] = gradient.views_per_group();
  if (timed) d["gpu_ms"] = {{"forward", forward_ms}, {"backward", backward_ms}};
  return out;
}


SolverOutput run_diffdvr_solver(VoxelProblem& p, const SolverSettings& s) { return solve_with_diffdvr(p, s); }

}  // namespace tfm
