// The paper's CPU baselines as solvers: `eigen-normal-equations` (explicit sparse A, A^T A and
// A^T b by Eigen sparse products, then the host tridiagonal solve) and `eigen-cgls` (Jacobi-
// preconditioned CGLS on the explicit A as one 4N-unknown system). Both read the host volumes.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "tfmatch/model/parameter_names.h"
#include "tfmatch/solvers/cgls_cpu.h"
#include "tfmatch/solvers/eigen_baseline.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {
namespace {

ExplicitSystem build_system(const VoxelProblem& p) {
  return build_explicit_system(p.ref_volume.values, p.opt_volume.values, p.ref_map, p.opt_map, p.ref_tf);
}

SolverOutput solve_with_eigen_normal_equations(VoxelProblem& p, const SolverArgs& args) {
  SolverOutput out;
  const uint32_t n = p.opt_map.tf_size;
  auto t0 = std::chrono::steady_clock::now();
  const ExplicitSystem sys = build_system(p);
  out.phases.push_back({"build A", ms_since(t0), -1.0});
  t0 = std::chrono::steady_clock::now();
  NormalEquations eq = to_tridiagonal(explicit_normal_equations(sys), n);
  eq.voxels = uint64_t(sys.b.size() / 4);
  for (int c = 0; c < 4; ++c) {
    double btb = 0.0;
    for (Eigen::Index i = c; i < sys.b.size(); i += 4) btb += sys.b[i] * sys.b[i];
    eq.btb[size_t(c)] = btb;
  }
  out.phases.push_back({"A^T A", ms_since(t0), -1.0});
  solve_and_record(eq, args.solve, out);
  out.details["nonzeros"] = sys.a.nonZeros();
  return out;
}

// R = ridge I + smooth D^T D on each channel of the interleaved 4N unknowns (absolute weights).
Eigen::SparseMatrix<double> interleaved_regularization(uint32_t n, const Regularization& reg) {
  Eigen::SparseMatrix<double> r(4 * n, 4 * n);
  if (reg.ridge == 0.0 && reg.smooth == 0.0) return r;
  std::vector<Eigen::Triplet<double>> t;
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) {
      const int k = int(4 * j) + c;
      t.emplace_back(k, k, reg.ridge + reg.smooth * ((j == 0 || j + 1 == n) ? 1.0 : 2.0));
      if (j + 1 < n) t.emplace_back(k, k + 4, -reg.smooth), t.emplace_back(k + 4, k, -reg.smooth);
    }
  r.setFromTriplets(t.begin(), t.end());
  return r;
}

SolverOutput solve_with_eigen_cgls(VoxelProblem& p, const SolverArgs& args) {
  CglsOptions o;
  o.tolerance = args.number("tolerance");
  o.max_iterations = uint32_t(args.integer("max-iterations"));
  const SolveOptions& solve = args.solve;
  SolverOutput out;
  const uint32_t n = p.opt_map.tf_size;
  auto t0 = std::chrono::steady_clock::now();
  const ExplicitSystem sys = build_system(p);
  if (sys.b.size() == 0) throw std::runtime_error("no voxel has data in both fields (all NaN?): nothing to fit");
  out.phases.push_back({"build A", ms_since(t0), -1.0});
  t0 = std::chrono::steady_clock::now();
  Regularization reg;
  if (solve.ridge > 0.0 || solve.smooth > 0.0) {
    // mean(diag M) from the squared column norms of A (channel 0 columns).
    double sum = 0.0;
    for (Eigen::Index row = 0; row < sys.a.outerSize(); row += 4)
      for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(sys.a, row); it; ++it)
        sum += it.value() * it.value();
    reg = {solve.ridge * sum / n, solve.smooth * sum / n};
  }
  const CglsResult r = cgls_jacobi(sys.a, sys.b, interleaved_regularization(n, reg), o);
  out.phases.push_back({"iterate", ms_since(t0), -1.0});
  Eigen::Matrix<double, Eigen::Dynamic, 4> x(n, 4);
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) x(j, c) = r.x[4 * j + c];
  uint32_t clamped = 0;
  out.tf = clamp_to_tf(x, &clamped);
  out.details["iterations"] = r.iterations;
  out.details["relative_residual"] = r.relative_residual;
  out.details["tolerance"] = o.tolerance;
  out.details["clamped_values"] = clamped;
  out.details["nonzeros"] = sys.a.nonZeros();
  if (!r.converged) {
    std::ostringstream os;
    os << "eigen-cgls stopped after " << r.iterations << " iterations with relative residual " << r.relative_residual
       << " above " << parameter("tolerance") << " " << o.tolerance;
    out.warnings.push_back(os.str());
  }
  return out;
}


class EigenNormalEquationsSolver final : public Solver {
 public:
  std::string_view name() const override { return "eigen-normal-equations"; }
  std::string_view summary() const override {
    return "CPU baseline: explicit sparse A, A^T A and A^T b by Eigen sparse products, then the tridiagonal solve";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, true, true, true}; }
  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    return solve_with_eigen_normal_equations(p, args);
  }
};

class EigenCglsSolver final : public Solver {
 public:
  std::string_view name() const override { return "eigen-cgls"; }
  std::string_view summary() const override {
    return "CPU baseline: Jacobi-preconditioned CGLS on the explicit sparse A (Eigen, double precision)";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, true, true}; }
  std::vector<SolverOption> options() const override { return cgls_stop_options(); }
  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override { return solve_with_eigen_cgls(p, args); }
};

}  // namespace

std::unique_ptr<Solver> make_eigen_normal_equations_solver() { return std::make_unique<EigenNormalEquationsSolver>(); }
std::unique_ptr<Solver> make_eigen_cgls_solver() { return std::make_unique<EigenCglsSolver>(); }

}  // namespace tfm
