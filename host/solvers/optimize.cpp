// run_optimize(): the shared pipeline of every solver.
#include "tfmatch/solvers/optimize.h"

#include <chrono>
#include <cmath>
#include <future>
#include <iomanip>
#include <optional>
#include <stdexcept>

#include "tfmatch/kernels/device_memory.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/model/phase_timer.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {

OptimizeResult run_optimize(Context& ctx, const OptimizeRequest& req) {
  if (!req.ref || !req.field) throw std::invalid_argument("run_optimize: both fields are required");
  if (req.tf_size < 2) throw std::runtime_error(parameter("tf-size") + " must be at least 2");
  const Solver& solver = require_solver(req.solver);
  const SolverArgs args = parse_solver_args(solver, req.settings);
  require_same_grid(*req.ref, *req.field);

  OptimizeResult out;
  out.solver = req.solver;
  out.device = ctx.device_name();
  out.voxels_total = req.ref->voxel_count();
  if (std::string w = grid_geometry_warning(*req.ref, *req.field); !w.empty()) out.warnings.push_back(std::move(w));
  const FieldRange* ref_user = req.ref_range ? &*req.ref_range : (req.ref_tf.range ? &*req.ref_tf.range : nullptr);
  // The two fields' min/max side by side (a read of each field from memory).
  std::future<FieldRange> field_range = std::async(std::launch::async, [&] {
    return resolve_range(req.field->values, req.field_range ? &*req.field_range : nullptr, req.field->name);
  });
  out.ref_range = resolve_range(req.ref->values, ref_user, req.ref->name);
  out.field_range = field_range.get();
  // A range from a TF file or the user can miss the field (a [0, 1] TF on temperatures in K):
  // every voxel would clamp to one entry and the fit would look perfect. Say so, or stop.
  if (ref_user) {
    const std::string source = req.ref_range ? "the given reference range" : "the reference TF file's range";
    std::string w = check_range_coverage(req.ref->values, out.ref_range, req.ref->name, source, req.allow_out_of_range);
    if (!w.empty()) out.warnings.push_back(std::move(w));
  }
  if (req.field_range) {
    std::string w = check_range_coverage(req.field->values, out.field_range, req.field->name, "the given field range",
                                         req.allow_out_of_range);
    if (!w.empty()) out.warnings.push_back(std::move(w));
  }

  auto t0 = std::chrono::steady_clock::now();
  // On a CPU device the fields are read where they are in host memory (the request's volumes
  // outlive these views); elsewhere they are uploaded, after a check that the device holds them.
  std::optional<DeviceField> ref_in_place = DeviceField::in_host_memory(ctx, req.ref->values, "reference field", req.max_chunk_voxels);
  std::optional<DeviceField> opt_in_place = DeviceField::in_host_memory(ctx, req.field->values, "second field", req.max_chunk_voxels);
  const uint64_t copies = (ref_in_place ? 0 : 1) + (opt_in_place ? 0 : 1);
  if (copies) check_device_memory(ctx, copies * req.ref->values.size() * sizeof(float), "uploading the fields");
  DeviceField ref = ref_in_place ? std::move(*ref_in_place) : DeviceField(ctx, req.ref->values, "reference field", req.max_chunk_voxels);
  DeviceField opt = opt_in_place ? std::move(*opt_in_place) : DeviceField(ctx, req.field->values, "second field", req.max_chunk_voxels);
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
  // Before: the second field shown with the reference TF, as a user would without tfmatch. With
  // as many entries as the optimized TF it is the system's own loss; else the field maps to the
  // reference TF's entries and the assembly sums that loss in the same pass.
  const FieldMapping opt_with_ref_tf = make_mapping(out.field_range, static_cast<uint32_t>(req.ref_tf.size()));
  if (opt_with_ref_tf.tf_size != problem.opt_map.tf_size) problem.before_map = opt_with_ref_tf;

  // The MAE pass's pipeline compiles on a thread of its own while the solver runs: a driver
  // compiles a pipeline for tens of milliseconds or more (lavapipe: the assembly's ~120 ms and
  // this one's ~65 ms at every start, its pipeline cache holding nothing; a GPU driver on a cold
  // cache), and the two need not wait for each other. Joined before `loss_kernel` goes, also on
  // an exception (a std::async future waits when destroyed).
  std::optional<VoxelLossKernel> loss_kernel;
  std::future<void> loss_kernel_ready;
  if (req.voxel_mae) {
    loss_kernel.emplace(ctx);
    loss_kernel_ready = std::async(std::launch::async, [&kernel = *loss_kernel] {
      const UntimedThread overlapped;  // counted as the wait below
      kernel.prepare(/*with_before=*/true);
    });
  }

  checkpoint("solve");  // every solver passes here, however few steps of its own it checks
  SolverOutput solved = solver.solve(problem, args);
  for (auto& p : solved.phases) out.phases.push_back(p);
  out.warnings.insert(out.warnings.end(), solved.warnings.begin(), solved.warnings.end());
  out.details = solved.details;
  out.tf = solved.tf;
  out.tf.range = out.field_range;

  // The voxel loss of any TF x follows from the system: ||S x - b||^2 = x^T M x - 2 x^T S^T b +
  // b^T b. The solvers that work on M assembled it already; the others need one pass here.
  std::vector<PhaseTime> assembled;
  const NormalEquations& eq = assembled_system(problem, &assembled);
  if (!assembled.empty()) out.phases.push_back({"assemble for loss", assembled[0].wall_ms, assembled[0].gpu_ms});
  if (eq.voxels == 0)
    throw std::runtime_error("no voxel has data in both " + req.ref->name + " and " + req.field->name);
  if (auto w = unreferenced_entries_warning(eq, out.tf, args.solve, out.warnings)) out.warnings.push_back(*w);
  t0 = std::chrono::steady_clock::now();
  out.before = voxel_loss_before(eq, req.ref_tf.as_floats());
  out.phases.push_back({"loss before", ms_since(t0), -1.0});
  t0 = std::chrono::steady_clock::now();
  out.after = voxel_loss_from_system(eq, out.tf.as_floats());
  out.phases.push_back({"loss after", ms_since(t0), -1.0});

  if (req.voxel_mae) {
    t0 = std::chrono::steady_clock::now();
    Buffer opt_tf_buffer = upload_tf(ctx, out.tf, "optimized TF");
    {
      PhaseScope waiting(Phase::Pipelines);
      loss_kernel_ready.get();
    }
    double gpu_ms = -1.0;  // both losses in one pass over the voxels
    const VoxelLosses mae = voxel_losses_gpu(ctx, ref, opt, problem.ref_map, opt_with_ref_tf, problem.opt_map,
                                             ref_tf_buffer, opt_tf_buffer, &gpu_ms, &*loss_kernel);
    out.before.absolute = mae.before.absolute;
    out.after.absolute = mae.after.absolute;
    out.phases.push_back({"voxel MAE", ms_since(t0), gpu_ms});
  }
  return out;
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
    const double c = details["cond"].is_number() ? details["cond"].get<double>() : INFINITY;
    os << "  cond(M): " << std::setprecision(3) << c << "\n";
  }
  os << std::fixed << std::setprecision(5) << "  voxel RMSE (RGBA): " << before.rmse()
     << " with the reference TF -> " << after.rmse() << " optimized\n"
     << std::defaultfloat;
  for (const std::string& w : warnings) os << "  warning: " << w << "\n";
}

}  // namespace tfm
