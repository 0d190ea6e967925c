// The optional CUDA solvers (cuda/, TFMATCH_CUDA): registration, the clear error without a
// device, and — on a machine with a CUDA device — the matrix-free and cuSPARSE assemblies
// against the double-precision CPU references, and both solvers against the exact solution.
// Without a device the numeric tests are skipped with "no CUDA device".
#ifdef TFMATCH_HAVE_CUDA

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "cuda_solvers.h"
#include "eigen_baseline.h"
#include "solver_problem.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

#define REQUIRE_CUDA_DEVICE() \
  if (!cuda::device_available()) GTEST_SKIP() << "no CUDA device"

class CudaSolvers : public test::GpuTest {};

std::vector<float> tf_floats(const TransferFunction& tf) {
  std::vector<float> out;
  for (const auto& e : tf.rgba)
    for (double c : e) out.push_back(float(c));
  return out;
}

cuda::CsrView view(const ExplicitSystem& sys) {
  return {int(sys.a.rows()), int(sys.a.cols()), {sys.a.outerIndexPtr(), size_t(sys.a.rows()) + 1},
          {sys.a.innerIndexPtr(), size_t(sys.a.nonZeros())}, {sys.a.valuePtr(), size_t(sys.a.nonZeros())}};
}

TEST(CudaRegistration, BothSolversAreRegistered) {
  EXPECT_NE(find_solver("cuda-normal-equations"), nullptr);
  EXPECT_NE(find_solver("cuda-cgls"), nullptr);
}

TEST_F(CudaSolvers, WithoutADeviceTheSolversSayWhy) {
  if (cuda::device_available()) GTEST_SKIP() << "a CUDA device is present";
  test::SolverProblem p = test::make_solver_problem(100, 8, 6, 0.2, 0.8, 1);
  p.upload(ctx());
  for (const std::string name : {"cuda-normal-equations", "cuda-cgls"}) {
    try {
      p.solve(ctx(), name);
      ADD_FAILURE() << name << " ran without a CUDA device";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(name + ": no CUDA device available (cudaGetDeviceCount: "),
                std::string::npos)
          << e.what();
    }
  }
}

// Awkward sizes: 1, 13, 127 voxels, one past a block's 256 x 16 voxels, and a multi-block field.
TEST(CudaAssembly, DirectKernelMatchesCpuReference) {
  REQUIRE_CUDA_DEVICE();
  for (size_t voxels : {size_t(1), size_t(13), size_t(127), size_t(4097), size_t(300001)}) {
    const test::SolverProblem p = test::make_solver_problem(voxels, 16, 9, 0.0, 1.0, uint32_t(voxels), 0.1, 7);
    const NormalEquations cpu = p.cpu_equations();
    const cuda::DirectAssembly d = cuda::assemble_direct(p.ref_volume.values, p.opt_volume.values, p.ref_map,
                                                         p.opt_map, tf_floats(p.ref_tf));
    const NormalEquations gpu = NormalEquations::from_slots(16, d.slots);
    // Identical TF coordinates; each voxel's terms are float32 products (relative error 2^-23
    // at most, values <= 1) cut to 32.32 fixed point (2^-32): per voxel <= ~3e-7, summed.
    const double tol = 3e-7 * double(voxels) + 1e-9;
    EXPECT_EQ(gpu.voxels, cpu.voxels) << voxels;
    for (uint32_t j = 0; j < 16; ++j) {
      EXPECT_NEAR(gpu.diag[j], cpu.diag[j], tol) << voxels << " j " << j;
      if (j + 1 < 16) EXPECT_NEAR(gpu.off[j], cpu.off[j], tol) << voxels << " j " << j;
      for (int c = 0; c < 4; ++c) EXPECT_NEAR(gpu.rhs(j, c), cpu.rhs(j, c), tol) << voxels << " j " << j;
    }
    for (int c = 0; c < 4; ++c) EXPECT_NEAR(gpu.btb[size_t(c)], cpu.btb[size_t(c)], tol) << voxels;
    // Fixed-point sums do not depend on scheduling: a second run gives the same bits.
    const cuda::DirectAssembly again = cuda::assemble_direct(p.ref_volume.values, p.opt_volume.values, p.ref_map,
                                                             p.opt_map, tf_floats(p.ref_tf));
    EXPECT_EQ(again.slots, d.slots) << voxels;
  }
}

TEST(CudaAssembly, CusparseProductsMatchEigenProducts) {
  REQUIRE_CUDA_DEVICE();
  for (size_t voxels : {size_t(1), size_t(13), size_t(127), size_t(4097)}) {
    const test::SolverProblem p = test::make_solver_problem(voxels, 12, 7, 0.0, 1.0, uint32_t(voxels) + 5, 0.1, 5);
    ExplicitSystem sys =
        build_explicit_system(p.ref_volume.values, p.opt_volume.values, p.ref_map, p.opt_map, p.ref_tf);
    sys.a.makeCompressed();
    const NormalEquations eigen = to_tridiagonal(explicit_normal_equations(sys), 12);
    const cuda::CusparseAssembly cs = cuda::assemble_cusparse(view(sys), {sys.b.data(), size_t(sys.b.size())});
    ExplicitNormalEquations ene;
    ene.ata = Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>>(
        48, 48, Eigen::Index(cs.val.size()), cs.row_ptr.data(), cs.col.data(), cs.val.data());
    ene.atb = Eigen::Map<const Eigen::VectorXd>(cs.atb.data(), Eigen::Index(cs.atb.size()));
    const NormalEquations gpu = to_tridiagonal(ene, 12);
    // Both in double; only the summation order differs: <= voxels * 2^-52 per entry.
    const double tol = 1e-15 * double(voxels) + 1e-15;
    for (uint32_t j = 0; j < 12; ++j) {
      EXPECT_NEAR(gpu.diag[j], eigen.diag[j], tol) << voxels << " j " << j;
      if (j + 1 < 12) EXPECT_NEAR(gpu.off[j], eigen.off[j], tol) << voxels << " j " << j;
      for (int c = 0; c < 4; ++c) EXPECT_NEAR(gpu.rhs(j, c), eigen.rhs(j, c), tol) << voxels << " j " << j;
    }
  }
}

TEST_F(CudaSolvers, NormalEquationsMatchExactSolution) {
  REQUIRE_CUDA_DEVICE();
  test::SolverProblem p = test::make_solver_problem(20000, 32, 20, 0.2, 0.8, 11, 0.05, 23);
  p.upload(ctx());
  for (double smooth : {0.0, 0.05}) {
    SolverSettings s;
    s.solve.smooth = smooth;
    const SolveResult exact = solve_normal_equations(p.cpu_equations(), s.solve);
    const SolverOutput out = p.solve(ctx(), "cuda-normal-equations", s);
    // Double-precision assembly and the same host solve: differences are rounding of the sums
    // (~1e-12 relative) amplified by cond(M) (< 1e3 here).
    EXPECT_LT(test::max_difference(out.tf, exact.tf), 1e-8) << smooth;
    // The float32 matrix-free kernel agrees with the cuSPARSE assembly to ~3e-7 per voxel.
    EXPECT_LT(out.details["assembly_max_difference"].get<double>(), 3e-7 * 20000);
    EXPECT_GE(out.details["direct_assembly_gpu_ms"].get<double>(), 0.0);
    // Two runs give the same bits (cuSPARSE's default SpGEMM repeated its bits on an H100; the
    // SpMV is CSR algorithm 2).
    EXPECT_EQ(p.solve(ctx(), "cuda-normal-equations", s).tf.rgba, out.tf.rgba) << smooth;
  }
}

// The Vulkan solver tests' tolerance (test_solver_cgls.cpp): stop at 1e-6 with a Jacobi-scaled
// condition number below ~10; CUDA iterates in double, so 1e-5 bounds it with margin.
constexpr double kCudaCglsTolerance = 1e-5;

TEST_F(CudaSolvers, CglsMatchesExactSolution) {
  REQUIRE_CUDA_DEVICE();
  test::SolverProblem p = test::make_solver_problem(5000, 16, 12, 0.2, 0.8, 3);
  p.upload(ctx());
  const SolveResult exact = solve_normal_equations(p.cpu_equations());
  ASSERT_EQ(exact.clamped_values, 0u);
  const SolverOutput out = p.solve(ctx(), "cuda-cgls");
  EXPECT_LT(test::max_difference(out.tf, exact.tf), kCudaCglsTolerance);
  EXPECT_LE(out.details["relative_residual"].get<double>(), 1e-6);
  EXPECT_LE(out.details["iterations"].get<int>(), 16 + 4) << "CG on 16 unknowns needs ~16 iterations";
  EXPECT_TRUE(out.warnings.empty());
}

TEST_F(CudaSolvers, CglsRegularizedWithUnreferencedEntries) {
  REQUIRE_CUDA_DEVICE();
  test::SolverProblem p = test::make_solver_problem(6000, 24, 12, 0.2, 0.8, 6, 0.0, 13);
  p.opt_map = make_mapping({10.0, 30.0}, 24);  // entries above ~t = 0.6 see no voxel
  p.upload(ctx());
  const NormalEquations eq = p.cpu_equations();
  ASSERT_EQ(eq.diag[23], 0.0);
  for (double smooth : {0.0, 0.05}) {
    SolverSettings s;
    s.solve.smooth = smooth;
    s.solve.ridge = smooth / 10;
    const SolverOutput out = p.solve(ctx(), "cuda-cgls", s);
    EXPECT_TRUE(test::all_finite_in_box(out.tf));
    EXPECT_LT(test::max_difference(out.tf, solve_normal_equations(eq, s.solve).tf), kCudaCglsTolerance) << smooth;
  }
}

TEST_F(CudaSolvers, CglsIsBitIdenticalAndHonoursTheCap) {
  REQUIRE_CUDA_DEVICE();
  test::SolverProblem p = test::make_solver_problem(20000, 64, 30, 0.1, 0.9, 7, 0.05);
  p.upload(ctx());
  const SolverOutput a = p.solve(ctx(), "cuda-cgls");
  const SolverOutput b = p.solve(ctx(), "cuda-cgls");
  EXPECT_EQ(a.tf.rgba, b.tf.rgba);
  EXPECT_EQ(a.details["iterations_per_channel"], b.details["iterations_per_channel"]);
  SolverSettings s;
  s.extra["max-iterations"] = "3";
  const SolverOutput capped = p.solve(ctx(), "cuda-cgls", s);
  EXPECT_EQ(capped.details["iterations"].get<int>(), 3);
  EXPECT_FALSE(capped.warnings.empty());
  s.extra["tolerance"] = "2";
  EXPECT_THROW(p.solve(ctx(), "cuda-cgls", s), std::runtime_error);
}

}  // namespace
}  // namespace tfm

#endif  // TFMATCH_HAVE_CUDA
