// The optional CUDA solvers (cuda/, built when TFMATCH_CUDA is on): `cuda-normal-equations`
// (M and S^T b from the explicit CSR A with cuSPARSE SpGEMM/SpMV as the paper does, plus the
// matrix-free CUDA kernel timed for comparison, then the host tridiagonal solve) and `cuda-cgls`
// (Jacobi-preconditioned CGLS with cuSPARSE SpMV). Without a CUDA device they throw on use.
// Their own library (tfmatch_cuda_solvers, the package's `cuda` component), added to the registry
// by register_cuda_solvers(): tfmatch::tfmatch itself needs no CUDA.
#include "cuda_solver_registration.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "cuda_solvers.h"
#include "eigen_baseline.h"
#include "parameter_names.h"
#include "solver_support.h"

namespace tfm {
namespace {

cuda::CsrView csr_view(const ExplicitSystem& sys) {
  cuda::CsrView v;
  v.rows = int(sys.a.rows());
  v.cols = int(sys.a.cols());
  v.row_ptr = {sys.a.outerIndexPtr(), size_t(sys.a.rows()) + 1};
  v.col = {sys.a.innerIndexPtr(), size_t(sys.a.nonZeros())};
  v.val = {sys.a.valuePtr(), size_t(sys.a.nonZeros())};
  return v;
}

ExplicitSystem build_system(const VoxelProblem& p) {
  ExplicitSystem sys =
      build_explicit_system(p.ref_volume.values, p.opt_volume.values, p.ref_map, p.opt_map, p.ref_tf);
  if (sys.b.size() == 0) throw std::runtime_error("no voxel has data in both fields (all NaN?): nothing to fit");
  sys.a.makeCompressed();
  return sys;
}

SolverOutput solve_with_cuda_normal_equations(VoxelProblem& p, const SolverArgs& args) {
  cuda::require_device("cuda-normal-equations");
  SolverOutput out;
  const uint32_t n = p.opt_map.tf_size;
  auto t0 = std::chrono::steady_clock::now();
  const ExplicitSystem sys = build_system(p);
  out.phases.push_back({"build A", ms_since(t0), -1.0});

  t0 = std::chrono::steady_clock::now();
  const cuda::CusparseAssembly cs = cuda::assemble_cusparse(csr_view(sys), {sys.b.data(), size_t(sys.b.size())});
  ExplicitNormalEquations ene;
  ene.ata = Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>>(
      4 * n, 4 * n, Eigen::Index(cs.val.size()), cs.row_ptr.data(), cs.col.data(), cs.val.data());
  ene.atb = Eigen::Map<const Eigen::VectorXd>(cs.atb.data(), Eigen::Index(cs.atb.size()));
  NormalEquations eq = to_tridiagonal(ene, n);
  eq.voxels = uint64_t(sys.b.size() / 4);
  for (int c = 0; c < 4; ++c) {
    double btb = 0.0;
    for (Eigen::Index i = c; i < sys.b.size(); i += 4) btb += sys.b[i] * sys.b[i];
    eq.btb[size_t(c)] = btb;
  }
  out.phases.push_back({"cuSPARSE A^T A", ms_since(t0), cs.assemble_ms});

  // The matrix-free kernel on the same problem, for the comparison the paper makes.
  t0 = std::chrono::steady_clock::now();
  std::vector<float> tf_rgba;
  tf_rgba.reserve(p.ref_tf.size() * 4);
  for (const auto& e : p.ref_tf.rgba)
    for (double c : e) tf_rgba.push_back(float(c));
  const cuda::DirectAssembly direct =
      cuda::assemble_direct(p.ref_volume.values, p.opt_volume.values, p.ref_map, p.opt_map, tf_rgba);
  const NormalEquations direct_eq = NormalEquations::from_slots(n, direct.slots);
  out.phases.push_back({"direct kernel", ms_since(t0), direct.kernel_ms});
  double diff = 0.0;
  for (uint32_t j = 0; j < n; ++j) {
    diff = std::max(diff, std::abs(direct_eq.diag[j] - eq.diag[j]));
    if (j + 1 < n) diff = std::max(diff, std::abs(direct_eq.off[j] - eq.off[j]));
    for (int c = 0; c < 4; ++c) diff = std::max(diff, std::abs(direct_eq.rhs(j, c) - eq.rhs(j, c)));
  }

  solve_and_record(eq, args.solve, out);
  out.details["device"] = cuda::device_name();
  out.details["nonzeros"] = sys.a.nonZeros();
  out.details["upload_ms"] = cs.upload_ms;
  out.details["cusparse_assembly_gpu_ms"] = cs.assemble_ms;
  out.details["direct_assembly_gpu_ms"] = direct.kernel_ms;
  out.details["direct_upload_ms"] = direct.upload_ms;
  // Largest |M, S^T b| difference between the two assemblies (float32 products vs double).
  out.details["assembly_max_difference"] = diff;
  return out;
}

SolverOutput solve_with_cuda_cgls(VoxelProblem& p, const SolverArgs& args) {
  const double tolerance = args.number("tolerance");
  const uint32_t max_iterations = uint32_t(args.integer("max-iterations"));
  cuda::require_device("cuda-cgls");
  SolverOutput out;
  const uint32_t n = p.opt_map.tf_size;
  auto t0 = std::chrono::steady_clock::now();
  const ExplicitSystem sys = build_system(p);
  // diag(M) from the squared column norms of A (channel 0 columns), the regularization relative
  // to its mean (absolute_regularization) and the Jacobi diagonal 1 / diag(M + R).
  NormalEquations eq(n);
  for (Eigen::Index row = 0; row < sys.a.outerSize(); row += 4)
    for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(sys.a, row); it; ++it)
      eq.diag[size_t(it.col() / 4)] += it.value() * it.value();
  const Regularization reg = absolute_regularization(eq, args.solve);
  const Tridiagonal h = regularized_matrix(eq, reg);
  std::vector<double> inv_diag(n);
  for (uint32_t j = 0; j < n; ++j) inv_diag[j] = h.diag[j] > 0.0 ? 1.0 / h.diag[j] : 0.0;
  out.phases.push_back({"build A", ms_since(t0), -1.0});

  t0 = std::chrono::steady_clock::now();
  cuda::CglsParams prm;
  prm.n = n;
  prm.tolerance = tolerance;
  prm.max_iterations = max_iterations;
  prm.ridge = reg.ridge;
  prm.smooth = reg.smooth;
  prm.inv_diag = inv_diag;
  const cuda::CglsOutcome r = cuda::cgls(csr_view(sys), {sys.b.data(), size_t(sys.b.size())}, prm);
  const double total_ms = ms_since(t0);
  out.phases.push_back({"upload", r.upload_ms, -1.0});
  out.phases.push_back({"iterate", total_ms - r.upload_ms, r.iterate_ms});

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
  out.details["device"] = cuda::device_name();
  out.details["iterations"] = max_iter;
  out.details["iterations_per_channel"] = iters;
  out.details["relative_residual"] = worst;  // ||A^T r - R x|| / ||A^T b||, worst channel
  out.details["relative_residual_per_channel"] = residuals;
  out.details["tolerance"] = tolerance;
  out.details["clamped_values"] = clamped;
  out.details["nonzeros"] = sys.a.nonZeros();
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
    return "CUDA: A^T A and A^T b from the explicit CSR A by cuSPARSE (as the paper), host tridiagonal solve";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, true, true, true}; }
  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    return solve_with_cuda_normal_equations(p, args);
  }
};

class CudaCglsSolver final : public Solver {
 public:
  std::string_view name() const override { return "cuda-cgls"; }
  std::string_view summary() const override { return "CUDA: Jacobi-preconditioned CGLS with cuSPARSE SpMV"; }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, true, true}; }
  std::vector<SolverOption> options() const override { return cgls_stop_options(); }
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
