// Helpers shared by the solvers.
#include "tfmatch/solvers/solver_support.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/model/cameras.h"
#include "tfmatch/model/parameter_names.h"

namespace tfm {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

const NormalEquations& assembled_system(VoxelProblem& p, std::vector<PhaseTime>* phases) {
  if (!p.system) {
    const auto t0 = std::chrono::steady_clock::now();
    GpuNormalEquations gpu(p.ctx, p.opt_map.tf_size);
    const double gpu_ms =
        gpu.add(p.ref, p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer, p.before_map ? &*p.before_map : nullptr);
    p.system = gpu.result();
    if (phases) phases->push_back({"assemble", ms_since(t0), gpu_ms});
  }
  return *p.system;
}

JacobiSetup jacobi_setup(VoxelProblem& p, const SolveOptions& options, const NormalEquations* system) {
  JacobiSetup js;
  std::vector<PhaseTime> assembled;
  js.eq = system ? *system : assembled_system(p, &assembled);
  js.gpu_ms = assembled.empty() ? 0.0 : assembled[0].gpu_ms;
  if (js.eq.voxels == 0) throw std::runtime_error("no voxel has data in both fields (all NaN?): nothing to fit");
  js.reg = absolute_regularization(js.eq, options);
  const Tridiagonal h = regularized_matrix(js.eq, js.reg);
  js.inv_diag.resize(js.eq.n);
  for (uint32_t j = 0; j < js.eq.n; ++j) js.inv_diag[j] = h.diag[j] > 0.0 ? float(1.0 / h.diag[j]) : 0.0f;
  return js;
}

std::vector<SolverOption> weight_options() {
  return {SolverOption::choice("weights", "none", {"none", "visibility"},
                               "voxel weights: none, or how much the reference renderings over the cameras see each "
                               "voxel (transmittance to the eye, summed over cameras)"),
          SolverOption::integer("weight-views", 8, 1, 1024, "cameras of the visibility weights"),
          SolverOption::choice("cameras", "fibonacci", {"random", "fibonacci"},
                               "where the visibility weights' cameras stand: evenly spread (Fibonacci sphere) or seeded random"),
          SolverOption::integer("seed", 1, 0, std::numeric_limits<uint64_t>::max(),
                                "seed of the visibility weights' random cameras")};
}

std::optional<VisibilityWeights> requested_weights(VoxelProblem& p, const SolverArgs& args, SolverOutput& out) {
  out.details["weights"] = args.text("weights");
  if (args.text("weights") == "none") return std::nullopt;
  const auto t0 = std::chrono::steady_clock::now();
  const uint32_t views = uint32_t(args.integer("weight-views"));
  std::vector<OrbitCamera> cameras;
  if (args.text("cameras") == "fibonacci") {
    cameras = fibonacci_cameras(views, args.render.camera);
  } else {
    RandomCameras random(args.integer("seed"), args.render.camera);
    cameras = random.next(views);
  }
  const VolumeGeometry geometry = VolumeGeometry::from(p.ref_volume.dims, p.ref_volume.spacing, args.render.z_scale);
  const VisibilityWeightsKernel kernel(p.ctx, uint32_t(p.ref.chunk_count()));
  VisibilityWeights w = kernel.compute(p.ref, geometry, p.ref_map, p.ref_tf_buffer, args.render, cameras);
  out.phases.push_back({"visibility weights", ms_since(t0), w.gpu_ms});
  out.details["weight_views"] = views;
  out.details["weight_max_transmittance_sum"] = w.max_sum;
  return w;
}

NormalEquations weighted_system(VoxelProblem& p, const DeviceField& weights, SolverOutput& out) {
  const auto t0 = std::chrono::steady_clock::now();
  GpuNormalEquations gpu(p.ctx, p.opt_map.tf_size);
  const double gpu_ms = gpu.add(p.ref, p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer, nullptr, &weights);
  out.phases.push_back({"assemble (weighted)", ms_since(t0), gpu_ms});
  return gpu.result();
}

NormalEquations solved_system(VoxelProblem& p, const SolverArgs& args, SolverOutput& out) {
  const std::optional<VisibilityWeights> w = requested_weights(p, args, out);
  return w ? weighted_system(p, w->weights, out) : assembled_system(p, &out.phases);
}

std::vector<SolverOption> cgls_stop_options() {
  return {SolverOption::number("tolerance", 1e-6, {.min = 0.0, .max = 1.0, .min_open = true, .max_open = true},
                               "stop a channel at this relative residual ||S^T r - R x|| / ||S^T b||"),
          SolverOption::integer("max-iterations", 1000, 1, 1000000000, "iteration cap")};
}

DetailValue cond_detail(double cond) { return std::isfinite(cond) ? DetailValue(cond) : DetailValue("inf"); }

SolveResult solve_and_record(const NormalEquations& eq, const SolveOptions& options, SolverOutput& out) {
  const auto t0 = std::chrono::steady_clock::now();
  SolveResult r = solve_normal_equations(eq, options);
  out.phases.push_back({"solve", ms_since(t0), -1.0});
  out.tf = r.tf;
  out.warnings = r.warnings;
  out.details["factorization"] = r.factorization;
  out.details["cond"] = cond_detail(r.cond);
  out.details["error_amplification"] = cond_detail(r.error_amplification);  // what the warning weighs
  out.details["clamped_values"] = r.clamped_values;
  out.details["unreferenced_entries"] = r.unreferenced_entries;
  return r;
}

std::optional<std::string> unreferenced_entries_warning(const NormalEquations& eq, const TransferFunction& tf,
                                                        const SolveOptions& solve,
                                                        const std::vector<std::string>& warnings) {
  if (solve.smooth > 0 || eq.n != tf.size()) return std::nullopt;
  for (const std::string& w : warnings)
    if (w.find("touched by no voxel") != std::string::npos) return std::nullopt;
  const std::vector<float> rgba = tf.as_floats();
  uint32_t unreferenced = 0;
  for (uint32_t j = 0; j < eq.n; ++j)
    if (eq.diag[j] == 0.0 &&
        std::all_of(rgba.begin() + 4 * j, rgba.begin() + 4 * j + 4, [](float v) { return v == 0.0f; }))
      ++unreferenced;
  if (unreferenced == 0) return std::nullopt;
  return std::to_string(unreferenced) + " of the " + std::to_string(eq.n) +
         " TF entries are touched by no voxel: nothing in the data decides them, and the fit left them at 0 "
         "(transparent black); " + parameter("smooth") + " fills them from their neighbours";
}

TransferFunction clamp_to_tf(const Eigen::Matrix<double, Eigen::Dynamic, 4>& x, uint32_t* clamped) {
  TransferFunction tf;
  tf.rgba.resize(size_t(x.rows()));
  uint32_t moved = 0;
  for (Eigen::Index j = 0; j < x.rows(); ++j)
    for (int c = 0; c < 4; ++c) {
      const double v = std::isfinite(x(j, c)) ? x(j, c) : 0.0;
      const double k = std::clamp(v, 0.0, 1.0);
      moved += k != x(j, c) ? 1 : 0;
      tf.rgba[size_t(j)][size_t(c)] = k;
    }
  if (clamped) *clamped = moved;
  return tf;
}

TransferFunction tf_from_floats(const std::vector<float>& rgba, uint32_t* clamped) {
  Eigen::Matrix<double, Eigen::Dynamic, 4> x(Eigen::Index(rgba.size() / 4), 4);
  for (Eigen::Index j = 0; j < x.rows(); ++j)
    for (int c = 0; c < 4; ++c) x(j, c) = rgba[size_t(4 * j + c)];
  return clamp_to_tf(x, clamped);
}

}  // namespace tfm
