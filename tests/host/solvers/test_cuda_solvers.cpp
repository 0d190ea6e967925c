// The optional CUDA solvers (cuda/, TFMATCH_CUDA): registration, the clear error without a
// device, and — on a machine with a CUDA device — the matrix-free and cuSPARSE assemblies
// against the double-precision CPU references, and both solvers against the exact solution.
// Without a device the numeric tests are skipped with "no CUDA device".
#ifdef TFMATCH_HAVE_CUDA

#include <gtest/gtest.h>

#include <dlfcn.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "cli_runner.h"
#include "scoped_env.h"
#include "solver_problem.h"
#include "tfmatch/cuda/cuda_backend.h"
#include "tfmatch/solvers/eigen_baseline.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

// The plugin the test program names (TFMATCH_CUDA_PLUGIN: the build's).
const cuda::Backend& plugin() { return cuda::backend("test"); }

#define REQUIRE_CUDA_DEVICE() \
  if (!plugin().device_available()) GTEST_SKIP() << "no CUDA device"

class CudaSolvers : public test::GpuTest {};

template <class T>
std::vector<T> to_vector(const T* data, Eigen::Index count) {
  return std::vector<T>(data, data + count);
}

TEST(CudaRegistration, BothSolversAreRegistered) {
  EXPECT_NE(find_solver("cuda-normal-equations"), nullptr);
  EXPECT_NE(find_solver("cuda-cgls"), nullptr);
}

// The plugin's entry point hands out its Backend only to a loader built from the same
// cuda_solvers.h (the tag is its hash).
TEST(CudaPlugin, TheEntryPointChecksTheInterfaceTag) {
  const char* path = std::getenv("TFMATCH_CUDA_PLUGIN");
  ASSERT_TRUE(path && *path) << "the test program names the build's plugin";
  void* handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
  ASSERT_NE(handle, nullptr) << dlerror();
  const auto entry = reinterpret_cast<cuda::BackendEntry>(dlsym(handle, cuda::kBackendEntryName));
  ASSERT_NE(entry, nullptr);
  EXPECT_EQ(entry(nullptr), nullptr);
  EXPECT_EQ(entry("cuda_solvers.h:0000000000000000"), nullptr);
  EXPECT_EQ(&cuda::load_backend(path), &plugin());  // the loader's tag is the plugin's: the same object
  dlclose(handle);
  // Only the entry point is exported: the plugin's own code cannot interpose on the program's.
  const test::CliResult exported = test::run_shell(std::string("nm -D --defined-only ") + path);
  ASSERT_EQ(exported.exit_code, 0) << exported.output;
  EXPECT_NE(exported.output.find(" T tfmatch_cuda_backend"), std::string::npos) << exported.output;
  EXPECT_EQ(exported.output.find("_ZN3tfm"), std::string::npos) << exported.output;
}

TEST(CudaPlugin, FilesThatAreNoPluginAreClearErrors) {
  test::TempDir dir;
  std::ofstream(dir / "garbage.so") << "not a shared library";
  Dl_info libc{};
  ASSERT_NE(dladdr(reinterpret_cast<void*>(&std::printf), &libc), 0);  // a real library, no entry point
  const std::vector<std::pair<std::string, std::string>> cases{
      {dir / "missing.so", "cannot be loaded: "},
      {dir / "garbage.so", "cannot be loaded: "},
      {libc.dli_fname, "has no entry point tfmatch_cuda_backend: not a tfmatch CUDA plugin"}};
  for (const auto& [path, why] : cases) {
    try {
      cuda::load_backend(path);
      ADD_FAILURE() << path << " loaded";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("the CUDA solvers' plugin " + path + " " + why), std::string::npos)
          << e.what();
    }
  }
}

TEST(CudaPlugin, LooksWhereTheProgramAndTheInstallKeepIt) {
  const std::vector<std::string> named = cuda::plugin_candidates();
  EXPECT_EQ(named, std::vector<std::string>{std::getenv("TFMATCH_CUDA_PLUGIN")});
  const test::ScopedEnv unset("TFMATCH_CUDA_PLUGIN", std::nullopt);
  const std::vector<std::string> places = cuda::plugin_candidates();
  ASSERT_EQ(places.size(), 3u);
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe");
  EXPECT_EQ(places[0], (self.parent_path() / "libtfmatch_cuda.so").string());
  EXPECT_EQ(places[1].rfind(self.parent_path().parent_path().string() + "/lib", 0), 0u) << places[1];
  EXPECT_TRUE(places[1].ends_with("/tfmatch/libtfmatch_cuda.so")) << places[1];
  EXPECT_TRUE(std::filesystem::path(places[2]).is_absolute()) << places[2];
  EXPECT_TRUE(places[2].ends_with("/tfmatch/libtfmatch_cuda.so")) << places[2];
}

TEST_F(CudaSolvers, WithoutADeviceTheSolversSayWhy) {
  if (plugin().device_available()) GTEST_SKIP() << "a CUDA device is present";
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
    test::SolverProblem p = test::make_solver_problem(voxels, 16, 9, 0.0, 1.0, uint32_t(voxels), 0.1, 7);
    // Holes of every kind of no data (DESIGN.md: NaN and ±Inf) in either field.
    for (size_t i = 2; i < voxels; i += 7)
      p.ref_volume.values[i] = (i % 3 == 0) ? NAN : (i % 3 == 1) ? INFINITY : -INFINITY;
    for (size_t i = 4; i < voxels; i += 9) p.opt_volume.values[i] = (i % 2) ? INFINITY : -INFINITY;
    const NormalEquations cpu = p.cpu_equations();
    const auto fields = plugin().upload(p.ref_volume.values, p.opt_volume.values);
    const cuda::DirectAssembly d = plugin().assemble_direct(*fields, p.ref_map, p.opt_map, p.ref_tf.as_floats());
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
    const cuda::DirectAssembly again = plugin().assemble_direct(*fields, p.ref_map, p.opt_map, p.ref_tf.as_floats());
    EXPECT_EQ(again.slots, d.slots) << voxels;
  }
}

// S (x) I_4 as CSR: row 4 v + c of A has S's row v at columns 4 j + c.
cuda::DeviceSystem::Host expand_to_a(const cuda::DeviceSystem::Host& s) {
  cuda::DeviceSystem::Host a;
  const size_t rows = s.row_ptr.size() - 1;
  a.row_ptr.push_back(0);
  for (size_t v = 0; v < rows; ++v)
    for (int c = 0; c < 4; ++c) {
      for (int k = s.row_ptr[v]; k < s.row_ptr[v + 1]; ++k) {
        a.col.push_back(4 * s.col[size_t(k)] + c);
        a.val.push_back(s.val[size_t(k)]);
      }
      a.row_ptr.push_back(int(a.col.size()));
    }
  return a;
}

// S and b built on the device (count, scan, fill), S expanded to A = S (x) I_4, are the host's
// build_explicit_system() bit for bit: awkward sizes (one past a block of 256, several blocks),
// NaN and ±Inf voxels in either field, values outside both ranges (clamped coordinates), a
// reference TF that leaves [0, 1] (clamped b).
TEST(CudaAssembly, DeviceBuiltSystemIsTheHostSystemBitForBit) {
  REQUIRE_CUDA_DEVICE();
  for (size_t voxels : {size_t(1), size_t(13), size_t(257), size_t(4097), size_t(300001)}) {
    test::SolverProblem p = test::make_solver_problem(voxels, 12, 7, -0.2, 1.2, uint32_t(voxels) + 5, 0.1, 9);
    for (size_t i = 3; i < voxels; i += 11) p.ref_volume.values[i] = NAN;
    for (size_t i = 6; i < voxels; i += 23) p.opt_volume.values[i] = (i % 2) ? INFINITY : -INFINITY;
    for (size_t i = 8; i < voxels; i += 29) p.ref_volume.values[i] = INFINITY;
    for (size_t i = 5; i < voxels; i += 17) p.opt_volume.values[i] = (i % 2) ? 25.0f : 5.0f;  // outside [10, 20]
    for (size_t i = 7; i < voxels; i += 19) p.ref_volume.values[i] = (i % 2) ? 1.5f : -0.5f;
    ExplicitSystem host =
        build_explicit_system(p.ref_volume.values, p.opt_volume.values, p.ref_map, p.opt_map, p.ref_tf);
    host.a.makeCompressed();
    const auto fields = plugin().upload(p.ref_volume.values, p.opt_volume.values);
    const auto built = plugin().build_system(*fields, p.ref_map, p.opt_map, p.ref_tf.as_floats());
    const cuda::DeviceSystem& sys = *built;
    ASSERT_EQ(sys.voxels(), uint64_t(host.b.size() / 4)) << voxels;
    EXPECT_EQ(sys.nonzeros(), int64_t(host.a.nonZeros())) << voxels;
    const cuda::DeviceSystem::Host s = sys.download();
    ASSERT_EQ(s.row_ptr.size(), sys.voxels() + 1) << voxels;
    const cuda::DeviceSystem::Host a = expand_to_a(s);
    EXPECT_EQ(a.row_ptr, to_vector(host.a.outerIndexPtr(), host.a.rows() + 1)) << voxels;
    EXPECT_EQ(a.col, to_vector(host.a.innerIndexPtr(), host.a.nonZeros())) << voxels;
    EXPECT_EQ(a.val, to_vector(host.a.valuePtr(), host.a.nonZeros())) << voxels;
    EXPECT_EQ(s.b, to_vector(host.b.data(), host.b.size())) << voxels;

    // diag(M) and b^T b: device sums of a fixed shape against the host's sequential ones.
    const NormalEquations eigen = to_tridiagonal(explicit_normal_equations(host), 12);
    const std::vector<double> norms = sys.column_norms();
    const double tol = 1e-15 * double(voxels) + 1e-15;
    for (uint32_t j = 0; j < 12; ++j) EXPECT_NEAR(norms[j], eigen.diag[j], tol) << voxels << " j " << j;
    for (int c = 0; c < 4; ++c) {
      const double btb = host.b(Eigen::seq(c, host.b.size() - 1, 4)).squaredNorm();
      EXPECT_NEAR(sys.btb()[size_t(c)], btb, tol) << voxels << " c " << c;
    }
    // And the same bits on a second build.
    const auto again = plugin().build_system(*fields, p.ref_map, p.opt_map, p.ref_tf.as_floats());
    EXPECT_EQ(again->column_norms(), norms) << voxels;
    EXPECT_EQ(again->btb(), sys.btb()) << voxels;
  }
}

TEST(CudaAssembly, DeviceSystemWithoutDataAndWithBadArguments) {
  REQUIRE_CUDA_DEVICE();
  test::SolverProblem p = test::make_solver_problem(100, 8, 6, 0.2, 0.8, 1);
  std::fill(p.ref_volume.values.begin(), p.ref_volume.values.end(), NAN);
  const auto fields = plugin().upload(p.ref_volume.values, p.opt_volume.values);
  const auto empty = plugin().build_system(*fields, p.ref_map, p.opt_map, p.ref_tf.as_floats());
  EXPECT_EQ(empty->voxels(), 0u);
  EXPECT_EQ(empty->download().row_ptr, std::vector<int>{0});
  EXPECT_EQ(empty->column_norms(), std::vector<double>(8, 0.0));
  EXPECT_THROW(plugin().assemble_cusparse(*empty), std::invalid_argument);
  const std::vector<float> short_tf(4 * 5);
  EXPECT_THROW(plugin().build_system(*fields, p.ref_map, p.opt_map, short_tf), std::invalid_argument);
  const std::vector<float> one(99);
  EXPECT_THROW(plugin().upload(p.ref_volume.values, one), std::invalid_argument);
  // Objects the plugin did not make are refused, not misread.
  struct Foreign final : cuda::DeviceFields {};
  EXPECT_THROW(plugin().build_system(Foreign(), p.ref_map, p.opt_map, p.ref_tf.as_floats()), std::invalid_argument);
}

TEST(CudaAssembly, CusparseProductsMatchEigenProducts) {
  REQUIRE_CUDA_DEVICE();
  for (size_t voxels : {size_t(1), size_t(13), size_t(127), size_t(4097)}) {
    const test::SolverProblem p = test::make_solver_problem(voxels, 12, 7, 0.0, 1.0, uint32_t(voxels) + 5, 0.1, 5);
    ExplicitSystem sys =
        build_explicit_system(p.ref_volume.values, p.opt_volume.values, p.ref_map, p.opt_map, p.ref_tf);
    sys.a.makeCompressed();
    const NormalEquations eigen = to_tridiagonal(explicit_normal_equations(sys), 12);  // from A itself
    const auto fields = plugin().upload(p.ref_volume.values, p.opt_volume.values);
    const cuda::CusparseAssembly cs =
        plugin().assemble_cusparse(*plugin().build_system(*fields, p.ref_map, p.opt_map, p.ref_tf.as_floats()));
    // S^T S is n x n (A^T A = S^T S (x) I_4) and S^T B is A^T b interleaved.
    const Eigen::Map<const Eigen::SparseMatrix<double, Eigen::RowMajor>> sts(
        12, 12, Eigen::Index(cs.val.size()), cs.row_ptr.data(), cs.col.data(), cs.val.data());
    ASSERT_EQ(cs.stb.size(), 48u);
    for (Eigen::Index j = 0; j < 12; ++j)
      for (Eigen::Index k = 0; k < 12; ++k)
        if (std::abs(j - k) > 1) EXPECT_EQ(sts.coeff(j, k), 0.0) << voxels << " (" << j << ", " << k << ")";
    NormalEquations gpu(12);
    for (uint32_t j = 0; j < 12; ++j) {
      gpu.diag[j] = sts.coeff(j, j);
      if (j + 1 < 12) {
        gpu.off[j] = sts.coeff(j, j + 1);
        EXPECT_NEAR(sts.coeff(j + 1, j), gpu.off[j], 1e-15 * double(voxels) + 1e-15) << voxels << " j " << j;
      }
      for (int c = 0; c < 4; ++c) gpu.rhs(j, c) = cs.stb[4 * j + c];
    }
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
