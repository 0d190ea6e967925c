// The `normal-equations` solver: GPU assembly of M and S^T b, tridiagonal solve on the host.
#include "tfmatch/solvers/solver_normal_equations.h"

#include <cmath>

#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/solvers/solver_support.h"

namespace tfm {

NormalEquationsGpuResult solve_normal_equations_gpu(VoxelProblem& p, const SolveOptions& options) {
  NormalEquationsGpuResult out;
  const NormalEquations& eq = assembled_system(p, &out.phases);
  const auto t0 = std::chrono::steady_clock::now();
  out.solve = solve_normal_equations(eq, options);
  out.phases.push_back({"solve", ms_since(t0), -1.0});
  return out;
}

namespace {

class NormalEquationsSolver final : public Solver {
 public:
  std::string_view name() const override { return "normal-equations"; }
  std::string_view summary() const override {
    return "M and S^T b assembled on the GPU, tridiagonal LDL^T on the host (fast, exact up to clamping)";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, true, true, true}; }

  std::vector<SolverOption> options() const override { return weight_options(); }

  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    SolverOutput out;
    const SolveResult r = solve_and_record(solved_system(p, args, out), args.solve, out);
    out.details["lambda_min"] = r.lambda_min;
    out.details["lambda_max"] = r.lambda_max;
    out.details["ridge"] = args.solve.ridge;
    out.details["smooth"] = args.solve.smooth;
    return out;
  }
};

}  // namespace

std::unique_ptr<Solver> make_normal_equations_solver() { return std::make_unique<NormalEquationsSolver>(); }

}  // namespace tfm
