// The optional CUDA solvers (cuda/, built when TFMATCH_CUDA is on), both on the explicit system
// A = S (x) I_4 built on the device: `cuda-normal-equations` (M = S^T S and S^T b by cuSPARSE
// SpGEMM/SpMM as the paper does, the matrix-free CUDA kernel timed beside for comparison, then the
// host tridiagonal solve) and `cuda-cgls` (Jacobi-preconditioned CGLS with cuSPARSE SpMM). Without
// a CUDA device they throw on use. Their own library (tfmatch_cuda_solvers, the package's `cuda`
// component), added to the registry by register_cuda_solvers(): tfmatch::tfmatch itself needs no
// CUDA. The CUDA code is a plugin, loaded when a CUDA solver first runs (cuda_backend.h).
#include "tfmatch/cuda/cuda_solver_registration.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/SparseCore>

#include "tfmatch/cuda/cuda_backend.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {
namespace {

// Why the solver named `who` cannot run here (no plugin, or no CUDA device), or empty.
std::string cuda_unavailable(const std::string& who) {
  try {
    std::string why;
    if (!cuda::backend(who).device_available(&why)) return who + ": no CUDA device available (" + why + ")";
  } catch (const std::exception& e) {
    return e.what();
  }
  return {};
}

// The plugin with device 0 selected, or the reason there is none, led by the solver's name.
const cuda::Backend& device_backend(const std::string& who) {
  const cuda::Backend& backend = cuda::backend(who);
  backend.require_device(who);
  return backend;
}

// The fields on the device and A, b built there from them.
struct DeviceProblem {
  std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now();  // first: before the upload
  std::unique_ptr<cuda::DeviceFields> fields;
  std::unique_ptr<cuda::DeviceSystem> system;
  DeviceProblem(const cuda::Backend& backend, const VoxelProblem& p, std::span<const float> ref_tf, SolverOutput& out)
      : fields(backend.upload(p.ref_volume.values, p.opt_volume.values)),
        system(backend.build_system(*fields, p.ref_map, p.opt_map, ref_tf)) {
    if (system->voxels() == 0) throw std::runtime_error("no voxel has data in both fields (all NaN?): nothing to fit");
    out.phases.push_back({"upload", fields->upload_ms(), -1.0});
    out.phases.push_back({"build A", ms_since(started) - fields->upload_ms(), system->build_ms()});
  }
};

SolverOutput solve_with_cuda_normal_equations(VoxelProblem& p, const SolverArgs& args) {
  const cuda::Backend& backend = device_backend("cuda-normal-equations");
  SolverOutput out;
  const uint32_t n = p.opt_map.tf_size;
  const std::vector<float> ref_tf = p.ref_tf.as_floats();
  const DeviceProblem dev(backend, p, ref_tf, out);

  auto t0 = std::chrono::steady_clock::now();
  const cuda::CusparseAssembly cs = backend.assemble_cusparse(*dev.system);
  // M = S^T S (tridiagonal: A^T A = M (x) I_4) and S^T B, interleaved like A^T b.
  const Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>> sts(
      n, n, Eigen::Index(cs.val.size()), cs.row_ptr.data(), cs.col.data(), cs.val.data());
  NormalEquations eq(n);
  for (uint32_t j = 0; j < n; ++j) {
    eq.diag[j] = sts.coeff(j, j);
    if (j + 1 < n) eq.off[j] = sts.coeff(j, j + 1);
    for (int c = 0; c < 4; ++c) eq.rhs(j, c) = cs.stb[4 * j + c];
  }
  eq.voxels = dev.system->voxels();
  eq.btb = dev.system->btb();
  out.phases.push_back({"cuSPARSE S^T S", ms_since(t0), cs.assemble_ms});

  // The matrix-free kernel on the same fields, for the comparison the paper makes.
  t0 = std::chrono::steady_clock::now();
  const cuda::DirectAssembly direct = backend.assemble_direct(*dev.fields, p.ref_map, p.opt_map, ref_tf);
  const NormalEquations direct_eq = NormalEquations::from_slots(n, direct.slots);
  out.phases.push_back({"direct kernel", ms_since(t0), direct.kernel_ms});
  double diff = 0.0;
  for (uint32_t j = 0; j < n; ++j) {
    diff = std::max(diff, std::abs(direct_eq.diag[j] - eq.diag[j]));
    if (j + 1 < n) diff = std::max(diff, std::abs(direct_eq.off[j] - eq.off[j]));
    for (int c = 0; c < 4; ++c) diff = std::max(diff, std::abs(direct_eq.rhs(j, c) - eq.rhs(j, c)));
  }

  solve_and_record(eq, args.solve, out);
  out.details["device"] = backend.device_name();
  out.details["nonzeros"] = dev.system->nonzeros();
  out.details["upload_ms"] = dev.fields->upload_ms();
  out.details["build_a_gpu_ms"] = dev.system->build_ms();
  out.details["cusparse_assembly_gpu_ms"] = cs.assemble_ms;
  out.details["direct_assembly_gpu_ms"] = direct.kernel_ms;
  // Largest |M, S^T b| difference between the two assemblies (float32 products vs double).
  out.details["assembly_max_difference"] = diff;
  return out;
}

SolverOutput solve_with_cuda_cgls(VoxelProblem& p, const SolverArgs& args) {
  const double tolerance = args.number("tolerance");
  const uint32_t max_iterations = uint32_t(args.integer("max-iterations"));
  const cuda::Backend& backend = device_backend("cuda-cgls");
  SolverOutput out;
  const uint32_t n = p.opt_map.tf_size;
  const DeviceProblem dev(backend, p, p.ref_tf.as_floats(), out);
  // diag(M) from the squared column norms of A (channel 0 columns), the regularization relative
  // to its mean (absolute_regularization) and the Jacobi diagonal 1 / diag(M + R).
  NormalEquations eq(n);
  eq.diag = dev.system->column_norms();
  const Regularization reg = absolute_regularization(eq, args.solve);
  const Tridiagonal h = regularized_matrix(eq, reg);
  std::vector<double> inv_diag(n);
  for (uint32_t j = 0; j < n; ++j) inv_diag[j] = h.diag[j] > 0.0 ? 1.0 / h.diag[j] : 0.0;

  auto t0 = std::chrono::steady_clock::now();
  cuda::CglsParams prm;
  prm.n = n;
  prm.tolerance = tolerance;
  prm.max_iterations = max_iterations;
  prm.ridge = reg.ridge;
  prm.smooth = reg.smooth;
  prm.inv_diag = inv_diag;
  const cuda::CglsOutcome r = backend.cgls(*dev.system, prm);
  const double total_ms = ms_since(t0);
  out.phases.push_back({"set-up", r.setup_ms, -1.0});
  out.phases.push_back({"iterate", total_ms - r.setup_ms, r.iterate_ms});

  Eigen::Matrix<double, Eigen::Dynamic, 4> x(n, 4);
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) x(j, c) = r.x[4 * j + c];
  uint32_t clamped = 0;
  out.tf = clamp_to_tf(x, &clamped);
  std::vector<uint32_t> iters;
  std::vector<double> residuals;
  uint32_t max_iter = 0;
  double worst = 0.0;
  for (int c = 0; c < 4; ++c) {
    iters.push_back(r.iterations[size_t(c)]);
    residuals.push_back(r.relative_residual[size_t(c)]);
    max_iter = std::max(max_iter, r.iterations[size_t(c)]);
    worst = std::max(worst, r.relative_residual[size_t(c)]);
  }
  out.details["device"] = backend.device_name();
  out.details["iterations"] = max_iter;
  out.details["iterations_per_channel"] = iters;
  out.details["relative_residual"] = worst;  // ||A^T r - R x|| / ||A^T b||, worst channel
  out.details["relative_residual_per_channel"] = residuals;
  out.details["tolerance"] = tolerance;
  out.details["clamped_values"] = clamped;
  out.details["nonzeros"] = dev.system->nonzeros();
  out.details["ridge"] = args.solve.ridge;
  out.details["smooth"] = args.solve.smooth;
  if (worst > tolerance) {
    std::ostringstream os;
    os << "cuda-cgls stopped at " << parameter("max-iterations") << " " << max_iterations << " with relative residual "
       << worst << " above " << parameter("tolerance") << " " << tolerance;
    out.warnings.push_back(os.str());
  }
  return out;
}


class CudaNormalEquationsSolver final : public Solver {
 public:
  std::string_view name() const override { return "cuda-normal-equations"; }
  std::string_view summary() const override {
    return "CUDA: A^T A and A^T b by cuSPARSE from the explicit system built on the device (as the paper), host tridiagonal solve";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, true, true, true}; }
  std::string unavailable() const override { return cuda_unavailable(std::string(name())); }
  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    return solve_with_cuda_normal_equations(p, args);
  }
};

class CudaCglsSolver final : public Solver {
 public:
  std::string_view name() const override { return "cuda-cgls"; }
  std::string_view summary() const override { return "CUDA: Jacobi-preconditioned CGLS with cuSPARSE SpMM on the explicit system built on the device"; }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, true, true}; }
  std::vector<SolverOption> options() const override { return cgls_stop_options(); }
  std::string unavailable() const override { return cuda_unavailable(std::string(name())); }
  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override { return solve_with_cuda_cgls(p, args); }
};

}  // namespace

void register_cuda_solvers() {
  add_solvers([] {
    std::vector<std::unique_ptr<Solver>> list;
    list.push_back(std::make_unique<CudaNormalEquationsSolver>());
    list.push_back(std::make_unique<CudaCglsSolver>());
    return list;
  });
}

}  // namespace tfm
