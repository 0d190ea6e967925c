// run_optimize(): the shared pipeline of every voxel solver.
#include "optimize.h"
#include "solver_registry.h"

#include <chrono>
#include <cmath>
#include <iomanip>
#include <sstream>
#include <stdexcept>

namespace tfm {
namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

std::map<std::string, SolverFn>& solver_registry() {
  static std::map<std::string, SolverFn> registry{
      {"normal-equations", run_normal_equations_solver},
      {"cgls", run_cgls_solver},
      {"diffdvr", run_diffdvr_solver},
      {"eigen-normal-equations", run_eigen_normal_equations_solver},
      {"eigen-cgls", run_eigen_cgls_solver},
      {"gradient-descent", run_gradient_descent_solver},
      {"qp", run_qp_solver},
#ifdef TFMATCH_HAVE_CUDA
      {"cuda-normal-equations", run_cuda_normal_equations_solver},
      {"cuda-cgls", run_cuda_cgls_solver},
#endif
  };
  return registry;
}


std::vector<std::string> solver_names() {
  std::vector<std::string> names;
  for (auto& [name, fn] : solver_registry()) names.push_back(name);
  return names;
}

double SolverSettings::number(const std::string& name, double fallback) const {
  auto it = extra.find(name);
  if (it == extra.end()) return fallback;
  try {
    size_t used = 0;
    double v = std::stod(it->second, &used);
    if (used != it->second.size()) throw std::invalid_argument("junk");
    return v;
  } catch (const std::exception&) {
    throw std::runtime_error("--" + name + ": expected a number, got '" + it->second + "'");
  }
}

std::string SolverSettings::text(const std::string& name, const std::string& fallback) const {
  auto it = extra.find(name);
  return it == extra.end() ? fallback : it->second;
}

OptimizeResult run_optimize(Context& ctx, const OptimizeRequest& req) {
  if (!req.ref || !req.field) throw std::invalid_argument("run_optimize: both fields are required");
  if (req.tf_size < 2) throw std::runtime_error("--tf-size must be at least 2");
  auto solver = solver_registry().find(req.solver);
  if (solver == solver_registry().end()) {
    std::string names;
    for (auto& n : solver_names()) names += (names.empty() ? "" : ", ") + n;
    throw std::runtime_error("unknown solver '" + req.solver + "' (available: " + names + ")");
  }
  require_same_grid(*req.ref, *req.field);

  OptimizeResult out;
  out.solver = req.solver;
  out.device = ctx.device_name();
  out.voxels_total = req.ref->voxel_count();
  const FieldRange* ref_user = req.ref_range ? &*req.ref_range : (req.ref_tf.range ? &*req.ref_tf.range : nullptr);
  out.ref_range = resolve_range(req.ref->values, ref_user, req.ref->name);
  out.field_range = resolve_range(req.field->values, req.field_range ? &*req.field_range : nullptr, req.field->name);

  auto t0 = std::chrono::steady_clock::now();
  DeviceField ref(ctx, req.ref->values, "reference field", req.max_chunk_voxels);
  DeviceField opt(ctx, req.field->values, "second field", req.max_chunk_voxels);
  Buffer ref_tf_buffer = upload_tf(ctx, req.ref_tf, "reference TF");
  out.phases.push_back({"upload", ms_since(t0), -1.0});

  VoxelProblem problem{ctx,
                       *req.ref,
                       *req.field,
                       ref,
                       opt,
                       make_mapping(out.ref_range, static_cast<uint32_t>(req.ref_tf.size())),
                       make_mapping(out.field_range, req.tf_size),
                       req.ref_tf,
                       ref_tf_buffer,
                       req.ref_tf.resampled(req.tf_size)};

  // Before: the second field shown with the reference TF, as a user would without tfmatch.
  t0 = std::chrono::steady_clock::now();
  FieldMapping opt_with_ref_tf = make_mapping(out.field_range, static_cast<uint32_t>(req.ref_tf.size()));
  double gpu_ms = -1;
  out.before = voxel_loss_gpu(ctx, ref, opt, problem.ref_map, opt_with_ref_tf, ref_tf_buffer, ref_tf_buffer, &gpu_ms);
  out.phases.push_back({"loss before", ms_since(t0), gpu_ms});
  if (out.before.voxels == 0)
    throw std::runtime_error("no voxel has data in both " + req.ref->name + " and " + req.field->name);

  SolverOutput solved = solver->second(problem, req.settings);
  for (auto& p : solved.phases) out.phases.push_back(p);
  out.warnings = solved.warnings;
  out.details = solved.details;
  out.tf = solved.tf;
  out.tf.range = out.field_range;

  t0 = std::chrono::steady_clock::now();
  Buffer opt_tf_buffer = upload_tf(ctx, out.tf, "optimized TF");
  out.after = voxel_loss_gpu(ctx, ref, opt, problem.ref_map, problem.opt_map, ref_tf_buffer, opt_tf_buffer, &gpu_ms);
  out.phases.push_back({"loss after", ms_since(t0), gpu_ms});
  return out;
}

nlohmann::json OptimizeResult::to_json() const {
  nlohmann::json j;
  j["solver"] = solver;
  j["device"] = device;
  j["voxels"] = voxels_total;
  j["voxels_with_data"] = after.voxels;
  j["tf_size"] = tf.size();
  j["ref_range"] = {ref_range.lo, ref_range.hi};
  j["field_range"] = {field_range.lo, field_range.hi};
  j["voxel_rmse_before"] = before.rmse();
  j["voxel_rmse_after"] = after.rmse();
  j["voxel_mae_before"] = before.mae();
  j["voxel_mae_after"] = after.mae();
  auto phases_json = nlohmann::json::array();
  for (const PhaseTime& p : phases) {
    nlohmann::json pj{{"name", p.name}, {"wall_ms", p.wall_ms}};
    if (p.gpu_ms >= 0) pj["gpu_ms"] = p.gpu_ms;
    phases_json.push_back(pj);
  }
  j["phases"] = phases_json;
  j["warnings"] = warnings;
  j["details"] = details;
  return j;
}

void OptimizeResult::print_summary(std::ostream& os) const {
  os << "tfmatch optimize on " << device << "\n";
  os << "  voxels: " << voxels_total << " (" << after.voxels << " with data in both fields)\n";
  os << "  solver: " << solver;
  if (details.contains("factorization")) os << " (" << details["factorization"].get<std::string>() << ")";
  os << ", TF entries: " << tf.size() << "\n";
  os << "  ranges: reference [" << ref_range.lo << ", " << ref_range.hi << "], field [" << field_range.lo << ", "
     << field_range.hi << "]\n";
  os << "  time per phase:";
  for (const PhaseTime& p : phases) {
    os << "\n    " << std::left << std::setw(14) << p.name << std::right << std::fixed << std::setprecision(2)
       << std::setw(10) << p.wall_ms << " ms";
    if (p.gpu_ms >= 0) os << "  (GPU " << p.gpu_ms << " ms)";
  }
  os << std::defaultfloat << "\n";
  if (details.contains("cond")) {
    double c = details["cond"].is_number() ? details["cond"].get<double>() : INFINITY;
    os << "  cond(M): " << std::setprecision(3) << c << "\n";
  }
  os << std::fixed << std::setprecision(5) << "  voxel RMSE (RGBA): " << before.rmse()
     << " with the reference TF -> " << after.rmse() << " optimized\n"
     << std::defaultfloat;
  for (const std::string& w : warnings) os << "  warning: " << w << "\n";
}

// ---- the normal-equations solver ------------------------------------------------------------

SolverOutput solve_with_normal_equations(VoxelProblem& p, const SolverSettings& settings) {
  SolverOutput out;
  auto t0 = std::chrono::steady_clock::now();
  GpuNormalEquations gpu(p.ctx, p.opt_map.tf_size);
  double gpu_ms = gpu.add(p.ref, p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer);
  NormalEquations eq = gpu.result();
  out.phases.push_back({"assemble", ms_since(t0), gpu_ms});

  t0 = std::chrono::steady_clock::now();
  SolveResult r = solve_normal_equations(eq, settings.solve);
  out.phases.push_back({"solve", ms_since(t0), -1.0});
  out.tf = r.tf;
  out.warnings = r.warnings;
  out.details["factorization"] = r.factorization;
  out.details["cond"] = std::isfinite(r.cond) ? nlohmann::json(r.cond) : nlohmann::json("inf");
  out.details["lambda_min"] = r.lambda_min;
  out.details["lambda_max"] = r.lambda_max;
  out.details["unreferenced_entries"] = r.unreferenced_entries;
  out.details["clamped_values"] = r.clamped_values;
  out.details["ridge"] = settings.solve.ridge;
  out.details["smooth"] = settings.solve.smooth;
  return out;
}


SolverOutput run_normal_equations_solver(VoxelProblem& p, const SolverSettings& s) { return solve_with_normal_equations(p, s); }

}  // namespace tfm
