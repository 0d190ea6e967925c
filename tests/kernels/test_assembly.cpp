// Normal-equation assembly kernel against the double-precision CPU reference: awkward sizes,
// NaNs, both accumulation paths, split fields, determinism, and a 10^8-voxel accuracy case.
#include <cmath>
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "normal_equations_cpu.h"
#include "gpu_voxel_ops.h"
#include "normal_equations.h"
#include "test_data.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

struct Pair {
  std::vector<float> ref, opt;
};

// Random pair with NaNs, values outside the range (clamped), and values exactly on TF nodes.
Pair random_pair(size_t n, uint32_t seed, uint32_t tf_size) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.1f, 1.1f);
  Pair p{std::vector<float>(n), std::vector<float>(n)};
  for (size_t i = 0; i < n; ++i) {
    p.ref[i] = u(rng);
    p.opt[i] = 3.0f + 5.0f * u(rng);
    if (i % 7 == 3) p.opt[i] = 3.0f + 5.0f * float(rng() % tf_size) / float(tf_size - 1);  // on a node
    if (i % 11 == 5) p.ref[i] = NAN;
    if (i % 13 == 6) p.opt[i] = NAN;
  }
  return p;
}

using test::random_tf;

// Every term the kernel adds is non-negative, so per entry |GPU - CPU| <= (float rounding of at
// most 4 operations per term, 4 * 2^-24 relative) * entry + (fixed-point truncation, < 2^-32
// per term) * terms. 1e-6 relative covers the first with margin; the second is the absolute term.
void expect_close(const NormalEquations& gpu, const NormalEquations& cpu, uint64_t terms) {
  const double abs_tol = double(terms) * std::ldexp(1.0, -32) + 1e-12;
  auto check = [&](double g, double c, const char* what, size_t j) {
    ASSERT_LE(std::abs(g - c), 1e-6 * std::abs(c) + abs_tol) << what << "[" << j << "]: gpu " << g << " cpu " << c;
  };
  ASSERT_EQ(gpu.voxels, cpu.voxels);
  for (size_t j = 0; j < cpu.diag.size(); ++j) check(gpu.diag[j], cpu.diag[j], "diag", j);
  for (size_t j = 0; j < cpu.off.size(); ++j) check(gpu.off[j], cpu.off[j], "off", j);
  for (Eigen::Index j = 0; j < cpu.rhs.rows(); ++j)
    for (int c = 0; c < 4; ++c) check(gpu.rhs(j, c), cpu.rhs(j, c), "rhs", size_t(j * 4 + c));
  for (int c = 0; c < 4; ++c) check(gpu.btb[c], cpu.btb[c], "btb", c);
}

struct Case {
  size_t voxels;
  uint32_t tf_size;
  bool force_global;
  uint64_t chunk_voxels;  // 0: no forced split
};

class AssemblyVsCpu : public test::GpuTest, public ::testing::WithParamInterface<Case> {};

TEST_P(AssemblyVsCpu, MatchesDoubleReference) {
  const Case c = GetParam();
  Pair p = random_pair(c.voxels, 1234u + uint32_t(c.voxels), c.tf_size);
  TransferFunction ref_tf = random_tf(17, 99);
  FieldMapping ref_map = make_mapping({0.0, 1.0}, 17);
  FieldMapping opt_map = make_mapping({3.0, 8.0}, c.tf_size);
  DeviceField ref(ctx(), p.ref, "ref", c.chunk_voxels), opt(ctx(), p.opt, "opt", c.chunk_voxels);
  if (c.chunk_voxels) ASSERT_GT(ref.chunk_count(), 1u);
  Buffer tf = upload_tf(ctx(), ref_tf, "ref tf");
  GpuNormalEquations gpu(ctx(), c.tf_size, c.force_global);
  if (!c.force_global && c.tf_size <= 64) EXPECT_TRUE(gpu.kernel().uses_shared_memory());
  if (c.force_global || c.tf_size > 1000) EXPECT_FALSE(gpu.kernel().uses_shared_memory());
  gpu.add(ref, opt, ref_map, opt_map, tf);
  NormalEquations cpu = assemble_normal_equations_cpu(p.ref, p.opt, ref_map, opt_map, ref_tf);
  expect_close(gpu.result(), cpu, c.voxels);
}

INSTANTIATE_TEST_SUITE_P(Sizes, AssemblyVsCpu,
                         ::testing::Values(Case{1, 64, false, 0}, Case{13, 64, false, 0}, Case{127, 64, false, 0},
                                           Case{256, 64, false, 0}, Case{257, 64, false, 0},
                                           Case{8193, 2, false, 0}, Case{8193, 64, true, 0},
                                           Case{20000, 1500, false, 0}, Case{5000, 64, false, 1024},
                                           Case{100003, 256, false, 0}),
                         [](const ::testing::TestParamInfo<Case>& info) {
                           const Case& c = info.param;
                           return "v" + std::to_string(c.voxels) + "_n" + std::to_string(c.tf_size) +
                                  (c.force_global ? "_global" : "") +
                                  (c.chunk_voxels ? "_chunks" + std::to_string(c.chunk_voxels) : "");
                         });

using AssemblyTest = test::GpuTest;

TEST_F(AssemblyTest, AllNanFieldContributesNothing) {
  std::vector<float> ref(1000, 0.5f), opt(1000, NAN);
  DeviceField r(ctx(), ref, "ref"), o(ctx(), opt, "opt");
  TransferFunction tf = random_tf(8, 1);
  Buffer tfb = upload_tf(ctx(), tf, "tf");
  GpuNormalEquations gpu(ctx(), 16);
  gpu.add(r, o, make_mapping({0, 1}, 8), make_mapping({0, 1}, 16), tfb);
  NormalEquations eq = gpu.result();
  EXPECT_EQ(eq.voxels, 0u);
  for (double d : eq.diag) EXPECT_EQ(d, 0.0);
  EXPECT_THROW(solve_normal_equations(eq), std::runtime_error);
}

// Bit-identical results: across runs, between the shared-memory and global-atomic paths, and for
// any run length
// (integer sums do not depend on the order of additions).
TEST_F(AssemblyTest, DeterministicAcrossRunsAndPaths) {
  Pair p = random_pair(300000, 7, 64);
  TransferFunction ref_tf = random_tf(64, 3);
  FieldMapping rm = make_mapping({0.0, 1.0}, 64), om = make_mapping({3.0, 8.0}, 64);
  DeviceField ref(ctx(), p.ref, "ref"), opt(ctx(), p.opt, "opt");
  Buffer tf = upload_tf(ctx(), ref_tf, "tf");
  auto run = [&](bool force_global, uint32_t run_length = 0) {
    GpuNormalEquations gpu(ctx(), 64, force_global, run_length);
    gpu.add(ref, opt, rm, om, tf);
    NormalEquations eq = gpu.result();
    std::vector<double> all = eq.diag;
    all.insert(all.end(), eq.off.begin(), eq.off.end());
    all.insert(all.end(), eq.rhs.data(), eq.rhs.data() + eq.rhs.size());
    return all;
  };
  std::vector<double> first = run(false);
  for (int i = 0; i < 3; ++i) {
    std::vector<double> again = run(false);
    ASSERT_EQ(std::memcmp(first.data(), again.data(), first.size() * sizeof(double)), 0) << "run " << i;
  }
  std::vector<double> global = run(true);
  ASSERT_EQ(std::memcmp(first.data(), global.data(), first.size() * sizeof(double)), 0);
  for (uint32_t run_length : {1u, 3u, 64u}) {
    std::vector<double> other = run(false, run_length);
    ASSERT_EQ(std::memcmp(first.data(), other.data(), first.size() * sizeof(double)), 0) << "run " << run_length;
  }
}

// splitmix64: a cheap, reproducible stream for generating a large field chunk by chunk.
uint64_t splitmix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// 10^8 voxels streamed through one reusable pair of device chunks: the field is never held
// twice (nor whole) in memory. Every entry must match the double sum to 1e-6 relative.
TEST_F(AssemblyTest, HundredMillionVoxelsWithinOneMillionth) {
  const uint64_t total = 100'000'000, chunk = uint64_t(1) << 24;
  const uint32_t n = 64;
  TransferFunction ref_tf = random_tf(64, 5);
  FieldMapping rm = make_mapping({0.0, 1.0}, 64), om = make_mapping({0.0, 1.0}, n);
  Buffer tf = upload_tf(ctx(), ref_tf, "tf");
  GpuNormalEquations gpu(ctx(), n);
  NormalEquations cpu(n);
  std::vector<float> ref(chunk), opt(chunk);
  DeviceField dref(ctx(), chunk, "ref chunk"), dopt(ctx(), chunk, "opt chunk");
  for (uint64_t begin = 0; begin < total; begin += chunk) {
    const uint64_t count = std::min(chunk, total - begin);
    ref.resize(count), opt.resize(count);
    for (uint64_t i = 0; i < count; ++i) {
      uint64_t h = splitmix(begin + i);
      ref[i] = float(h & 0xFFFFFF) / float(0xFFFFFF);
      // A smooth function of the reference plus noise: M is dominated by the diagonal blocks.
      opt[i] = std::clamp(ref[i] * ref[i] + 0.05f * (float((h >> 24) & 0xFFFF) / 65535.0f - 0.5f), 0.0f, 1.0f);
    }
    if (count != chunk) {
      dref = DeviceField(ctx(), count, "ref tail");
      dopt = DeviceField(ctx(), count, "opt tail");
    }
    dref.upload(ref);
    dopt.upload(opt);
    gpu.add(dref, dopt, rm, om, tf);
    accumulate_normal_equations_cpu(cpu, ref, opt, rm, om, ref_tf);
  }
  NormalEquations g = gpu.result();
  ASSERT_EQ(g.voxels, total);
  ASSERT_EQ(cpu.voxels, total);
  double worst = 0.0;
  auto rel = [&](double a, double b) {
    if (b != 0.0) worst = std::max(worst, std::abs(a - b) / std::abs(b));
    else EXPECT_EQ(a, 0.0);
  };
  for (uint32_t j = 0; j < n; ++j) rel(g.diag[j], cpu.diag[j]);
  for (uint32_t j = 0; j + 1 < n; ++j) rel(g.off[j], cpu.off[j]);
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) rel(g.rhs(j, c), cpu.rhs(j, c));
  for (int c = 0; c < 4; ++c) rel(g.btb[c], cpu.btb[c]);
  RecordProperty("max_relative_error", std::to_string(worst));
  std::printf("10^8 voxels: max relative error of any entry %.3g\n", worst);
  EXPECT_LE(worst, 1e-6);
}

}  // namespace
}  // namespace tfm
