// Normal-equation assembly beyond its case table (host/selftest/selftest_voxel.cpp, run by
// test_kernel_cases.cpp: awkward sizes, NaNs, every mode and atomic width, split fields and
// ranges against the double reference, the exact fixed-point emulation and the loss before):
// an all-NaN field, the before loss only when asked, determinism across runs, paths and
// workgroup counts, term passes, unavailable paths, the losses, and a 10^8-voxel accuracy case.
#include <cmath>
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstring>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "test_data.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/voxel_loss.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/solvers/normal_equations.h"
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

// Every slot equals the CPU's exact emulation of the kernel's integer sums (bit for bit).
void expect_exact(const std::vector<uint64_t>& gpu, const std::vector<uint64_t>& exact) {
  ASSERT_EQ(gpu.size(), exact.size());
  for (size_t k = 0; k < exact.size(); ++k)
    ASSERT_EQ(gpu[k], exact[k]) << "fixed-point slot " << k << " (units of 2^-32)";
}

using AssemblyTest = test::GpuTest;

// Two kernels of the same kind made one after the other (two solvers' assemblies) make the driver
// create their pipelines once, and give the same sums: on a context of its own, whose registry
// starts empty.
TEST(AssemblyPipelines, KernelsMadeAgainReuseTheirPipelines) {
  const std::unique_ptr<Context> own = Context::create();
  Context& c = *own;
  std::vector<float> ref(5000), opt(5000);
  for (size_t i = 0; i < ref.size(); ++i) ref[i] = float(i % 97) / 96.0f, opt[i] = float((i * 7) % 89) / 88.0f;
  DeviceField r(c, ref, "ref"), o(c, opt, "opt");
  const Buffer tf_buffer = upload_tf(c, random_tf(8, 5), "tf");
  const FieldMapping map = make_mapping({0.0, 1.0}, 8), opt_map = make_mapping({0.0, 1.0}, 12);
  ASSERT_EQ(c.pipelines().size(), 0u);
  std::vector<uint64_t> first;
  size_t made = 0;
  for (int kernel = 0; kernel < 2; ++kernel) {
    GpuNormalEquations gpu(c, 12);
    gpu.add(r, o, map, opt_map, tf_buffer);
    const std::vector<uint64_t> slots = gpu.fixed_point_slots();
    if (kernel == 0) {
      first = slots;
      made = c.pipelines().size();
      EXPECT_GT(made, 0u) << "the assembly's pipelines did not come from the context's registry";
    } else {
      EXPECT_EQ(slots, first);
      EXPECT_EQ(c.pipelines().size(), made) << "the second kernel made pipelines of its own";
    }
  }
  for (const std::string& m : c.take_validation_messages()) ADD_FAILURE() << "Vulkan validation: " << m;
}

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

// Without a before mapping the system carries no before loss (its slots stay 0), and the loss
// before comes from the system (voxel_loss_before); one accumulation cannot mix the two.
TEST_F(AssemblyTest, BeforeLossOnlyWhenAskedAndNeverMixed) {
  Pair p = random_pair(5003, 21, 9);
  const TransferFunction ref_tf = random_tf(9, 22);
  const FieldMapping rm = make_mapping({0.0, 1.0}, 9), om = make_mapping({3.0, 8.0}, 9);
  DeviceField ref(ctx(), p.ref, "ref"), opt(ctx(), p.opt, "opt");
  Buffer tf = upload_tf(ctx(), ref_tf, "tf");
  GpuNormalEquations gpu(ctx(), 9);
  gpu.add(ref, opt, rm, om, tf);
  const std::vector<uint64_t> slots = gpu.fixed_point_slots();
  for (uint32_t c = 0; c < 4; ++c) EXPECT_EQ(slots[6 * 9 + 4 + c], 0u);
  const NormalEquations eq = gpu.result();
  EXPECT_FALSE(eq.before.has_value());
  // Same TF size: the before loss is the system's own loss of the reference TF, equal to the
  // direct sum (om maps the field onto the reference TF's 9 entries).
  const VoxelLoss before = voxel_loss_before(eq, ref_tf.as_floats());
  const std::array<double, 4> want = before_loss_cpu(p.ref, p.opt, rm, om, ref_tf);
  // x^T M x - 2 x^T S^T b + b^T b cancels: terms of up to ~4 per voxel, 1e-6 relative each.
  for (int c = 0; c < 4; ++c) EXPECT_NEAR(before.squared[c], want[c], 4e-6 * double(eq.voxels)) << "channel " << c;
  EXPECT_THROW(gpu.add(ref, opt, rm, om, tf, &om), std::invalid_argument);
  EXPECT_THROW(voxel_loss_before(eq, std::vector<float>(4 * 5, 0.5f)), std::invalid_argument);
  const FieldMapping wrong = make_mapping({3.0, 8.0}, 5);  // not the reference TF's size
  GpuNormalEquations other(ctx(), 9);
  EXPECT_THROW(other.add(ref, opt, rm, om, tf, &wrong), std::invalid_argument);
}

// Bit-identical totals across runs, modes, atomic widths and workgroup counts (integer sums do
// not depend on the order of additions), and equal to the exact CPU emulation.
TEST_F(AssemblyTest, DeterministicAcrossRunsPathsAndWorkgroups) {
  Pair p = random_pair(300001, 7, 64);
  TransferFunction ref_tf = random_tf(64, 3);
  FieldMapping rm = make_mapping({0.0, 1.0}, 64), om = make_mapping({3.0, 8.0}, 64);
  DeviceField ref(ctx(), p.ref, "ref"), opt(ctx(), p.opt, "opt");
  Buffer tf = upload_tf(ctx(), ref_tf, "tf");
  const std::vector<uint64_t> exact = assemble_normal_equations_fixed_point(p.ref, p.opt, rm, om, ref_tf);
  auto run = [&](ReductionOptions options) {
    GpuNormalEquations gpu(ctx(), 64, options);
    gpu.add(ref, opt, rm, om, tf);
    return gpu.fixed_point_slots();
  };
  for (int i = 0; i < 2; ++i) expect_exact(run({}), exact);
  for (ReductionMode mode : {ReductionMode::RunsShared, ReductionMode::RunsGlobal, ReductionMode::Private})
    for (AtomicWidth width : {AtomicWidth::Bits32, AtomicWidth::Bits64}) {
      if (width == AtomicWidth::Bits64 && !ctx().int64_atomics()) continue;
      if (mode == ReductionMode::Private && width == AtomicWidth::Bits32) continue;
      for (uint32_t groups : {1u, 3u, 64u}) {
        SCOPED_TRACE(std::string(reduction_mode_name(mode)) + (width == AtomicWidth::Bits64 ? ", 64-bit" : ", 32-bit") +
                     ", " + std::to_string(groups) + " workgroups");
        expect_exact(run({mode, width, groups}), exact);
      }
      // Lane lengths of the run modes' workgroups (bench --lane-voxels): from one quad per lane
      // (every segment one step) to lanes of several 64-step segments.
      if (mode == ReductionMode::Private) continue;
      for (uint32_t lane : {4u, 16u, 1000u}) {
        SCOPED_TRACE(std::string(reduction_mode_name(mode)) + (width == AtomicWidth::Bits64 ? ", 64-bit" : ", 32-bit") +
                     ", lanes of " + std::to_string(lane) + " voxels");
        ReductionOptions options{mode, width};
        options.lane_voxels = lane;
        expect_exact(run(options), exact);
      }
    }
}

// Fields read where they are in host memory (a CPU device: DeviceField::in_host_memory) give the
// exact sums of uploaded ones, whole and in chunks, from a large allocation (its own pages) and a
// small one (inside the heap), and leave the caller's values as they were.
TEST_F(AssemblyTest, FieldsInHostMemoryGiveTheExactSums) {
  if (ctx().properties().deviceType != VK_PHYSICAL_DEVICE_TYPE_CPU || !ctx().host_import())
    GTEST_SKIP() << ctx().device_name() << ": fields in host memory are for CPU devices that import host memory";
  TransferFunction ref_tf = random_tf(64, 5);
  const FieldMapping rm = make_mapping({0.0, 1.0}, 64), om = make_mapping({3.0, 8.0}, 64);
  const Buffer tf = upload_tf(ctx(), ref_tf, "tf");
  for (const size_t n : {size_t(13), size_t(5000), size_t(300001)}) {
    const Pair p = random_pair(n, 11, 64);
    const Pair before = p;
    const std::vector<uint64_t> exact = assemble_normal_equations_fixed_point(p.ref, p.opt, rm, om, ref_tf);
    for (const uint64_t chunk : {uint64_t(0), uint64_t(4096)}) {
      SCOPED_TRACE(std::to_string(n) + " voxels, chunks of " + (chunk ? std::to_string(chunk) : "the device's size"));
      std::optional<DeviceField> ref = DeviceField::in_host_memory(ctx(), p.ref, "ref", chunk);
      std::optional<DeviceField> opt = DeviceField::in_host_memory(ctx(), p.opt, "opt", chunk);
      ASSERT_TRUE(ref && opt);  // malloc's 16-byte alignment meets lavapipe's offset alignment
      EXPECT_TRUE(ref->in_host_memory());
      if (chunk) EXPECT_GT(ref->chunk_count(), n > chunk ? 1u : 0u);
      GpuNormalEquations gpu(ctx(), 64);
      gpu.add(*ref, *opt, rm, om, tf);
      expect_exact(gpu.fixed_point_slots(), exact);
      EXPECT_THROW(ref->upload(p.ref), std::logic_error);
    }
    ASSERT_EQ(std::memcmp(p.ref.data(), before.ref.data(), n * sizeof(float)), 0);
    ASSERT_EQ(std::memcmp(p.opt.data(), before.opt.data(), n * sizeof(float)), 0);
  }
}

// The multi-threaded CPU loop `tfmatch bench` compares against: the one-thread reference's sums
// to double rounding, for thread counts that split the voxels unevenly.
TEST(AssemblyCpuLoop, ThreadedMatchesOneThread) {
  Pair p = random_pair(100003, 31, 64);
  const TransferFunction ref_tf = random_tf(17, 32);
  const FieldMapping rm = make_mapping({0.0, 1.0}, 17), om = make_mapping({3.0, 8.0}, 64);
  const NormalEquations one = assemble_normal_equations_cpu(p.ref, p.opt, rm, om, ref_tf);
  for (unsigned threads : {2u, 3u, 7u}) {
    const NormalEquations many = assemble_normal_equations_cpu_threaded(p.ref, p.opt, rm, om, ref_tf, threads);
    ASSERT_EQ(many.voxels, one.voxels);
    for (uint32_t j = 0; j < 64; ++j) {
      EXPECT_NEAR(many.diag[j], one.diag[j], 1e-12 * one.diag[j]) << threads << " threads, entry " << j;
      for (int c = 0; c < 4; ++c) EXPECT_NEAR(many.rhs(j, c), one.rhs(j, c), 1e-12 * std::abs(one.rhs(j, c)) + 1e-15);
    }
    for (uint32_t j = 0; j + 1 < 64; ++j) EXPECT_NEAR(many.off[j], one.off[j], 1e-12 * one.off[j]);
    for (int c = 0; c < 4; ++c) EXPECT_NEAR(many.btb[c], one.btb[c], 1e-12 * one.btb[c]);
  }
  // What a worker throws reaches the caller (it ended the program through std::terminate).
  EXPECT_THROW(assemble_normal_equations_cpu_threaded(p.ref, p.opt, rm, om, random_tf(9, 32), 3), std::invalid_argument);
}

// Private passes: every one of the 11 bin terms in exactly one pass, in order, each pass's
// histogram (terms x entries) within kPrivateHistogramSlots, every pass but the last of the same
// number of terms (the passes are rows of one pipeline); the other modes take all at once.
TEST(AssembleTermPasses, CoverEveryTermOnceWithinTheBudget) {
  for (uint32_t n : {2u, 64u, 1024u, 1025u, 2048u, 3000u, 4096u}) {
    const auto passes = assemble_term_passes(ReductionMode::Private, n);
    uint32_t next = 0;
    for (const auto& p : passes) {
      EXPECT_EQ(p.first, next) << n;
      EXPECT_GE(p.count, 1u);
      if (&p != &passes.back()) EXPECT_EQ(p.count, passes.front().count) << n;
      EXPECT_LE(p.count, passes.front().count) << n;
      EXPECT_LE(uint64_t(p.count) * n, kPrivateHistogramSlots) << n;
      next += p.count;
    }
    EXPECT_EQ(next, 11u) << n;
    // The fewest passes: one pass fewer cannot hold all 11 terms within the budget.
    const uint64_t per_pass_max = std::max<uint64_t>(1, kPrivateHistogramSlots / n);
    EXPECT_LT((passes.size() - 1) * per_pass_max, 11u) << n;
  }
  const auto runs = assemble_term_passes(ReductionMode::RunsShared, 4096);
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0].count, 11u);
}

// A path the device cannot run is an error naming what is missing, never a silent fallback.
TEST_F(AssemblyTest, UnavailablePathsThrow) {
  const uint32_t too_big = ctx().limits().maxComputeSharedMemorySize / 8;  // > (6N+4) * 8 bytes
  EXPECT_THROW(GpuNormalEquations(ctx(), too_big, {ReductionMode::RunsShared}), std::runtime_error);
  EXPECT_THROW(GpuNormalEquations(ctx(), private_limit(ctx(), kAssemblePrivateMaxBins) + 1, {ReductionMode::Private}),
               std::runtime_error);
  EXPECT_THROW(GpuNormalEquations(ctx(), 64, {ReductionMode::Private, AtomicWidth::Bits32}), std::runtime_error);
  if (!ctx().int64_atomics()) EXPECT_THROW(GpuNormalEquations(ctx(), 64, {ReductionMode::Auto, AtomicWidth::Bits64}), std::runtime_error);
  EXPECT_THROW(GpuNormalEquations(ctx(), 1), std::invalid_argument);
}

// The voxel loss of any TF follows from the system, x^T M x - 2 x^T S^T b + b^T b per channel:
// it equals the direct double-precision sum over the voxels of (T_o(F_o) - b)^2. Bound per
// channel: M, S^T b and b^T b carry float rounding of their terms (at most 4 operations of 2^-24
// relative) and 2^-32 truncation per term, so the three parts move by 1e-6 of their magnitudes
// plus 2^-31 per voxel; the direct sum rounds the same float colours in double.
TEST_F(AssemblyTest, LossFromSystemEqualsDirectVoxelLoss) {
  const uint32_t n = 23;
  Pair p = random_pair(40001, 11, n);
  const TransferFunction ref_tf = random_tf(17, 4), opt_tf = random_tf(n, 5);
  const FieldMapping rm = make_mapping({0.0, 1.0}, 17), om = make_mapping({3.0, 8.0}, n);
  DeviceField ref(ctx(), p.ref, "ref"), opt(ctx(), p.opt, "opt");
  Buffer rtf = upload_tf(ctx(), ref_tf, "ref tf");
  GpuNormalEquations gpu(ctx(), n);
  gpu.add(ref, opt, rm, om, rtf);
  const NormalEquations eq = gpu.result();
  const std::vector<float> x = opt_tf.as_floats(), r = ref_tf.as_floats();
  const VoxelLoss from_system = voxel_loss_from_system(eq, x);

  std::array<double, 4> direct{};
  uint64_t counted = 0;
  for (size_t i = 0; i < p.ref.size(); ++i) {
    uint32_t jr, jo;
    float wr, wo;
    if (!tf_coordinate(p.ref[i], rm, jr, wr) || !tf_coordinate(p.opt[i], om, jo, wo)) continue;
    ++counted;
    for (int c = 0; c < 4; ++c) {
      const double b = std::clamp((1.0 - wr) * r[4 * jr + c] + double(wr) * r[4 * (jr + 1) + c], 0.0, 1.0);
      const double v = (1.0 - wo) * x[4 * jo + c] + double(wo) * x[4 * (jo + 1) + c];
      direct[c] += (v - b) * (v - b);
    }
  }
  ASSERT_EQ(from_system.voxels, counted);
  Eigen::Matrix<double, Eigen::Dynamic, 4> xm(n, 4);
  for (uint32_t j = 0; j < n; ++j)
    for (int c = 0; c < 4; ++c) xm(j, c) = x[4 * j + c];
  for (int c = 0; c < 4; ++c) {
    double xmx = 0.0;
    for (uint32_t j = 0; j < n; ++j) {
      xmx += eq.diag[j] * xm(j, c) * xm(j, c);
      if (j + 1 < n) xmx += 2.0 * std::abs(eq.off[j] * xm(j, c) * xm(j + 1, c));
    }
    const double magnitude = xmx + 2.0 * std::abs(xm.col(c).dot(eq.rhs.col(c))) + eq.btb[c];
    const double bound = 1e-6 * magnitude + double(counted) * std::ldexp(1.0, -31);
    EXPECT_NEAR(from_system.squared[c], direct[c], bound) << "channel " << c;
    EXPECT_TRUE(std::isnan(from_system.absolute[c]));
  }
  // The same against the kernel that measures it directly on the voxels.
  Buffer otf = upload_tf(ctx(), opt_tf, "opt tf");
  const VoxelLoss measured = voxel_loss_gpu(ctx(), ref, opt, rm, om, rtf, otf);
  EXPECT_NEAR(from_system.rmse(), measured.rmse(), 1e-6 * measured.rmse());
  EXPECT_THROW(voxel_loss_from_system(eq, std::vector<float>(4 * (n + 1), 0.5f)), std::invalid_argument);
}

// The voxel-loss kernel: its fixed-point words are the same for every workgroup size, range
// split and chunking; with a before mapping the one pass gives, in its two halves, the words of
// the two single-loss passes (after, then before); and the sums match the double loop.
TEST_F(AssemblyTest, VoxelLossesInOnePassAreTheSingleLossesBitForBit) {
  const uint32_t n = 23;
  const Pair p = random_pair(20011, 41, n);  // 20011 % 4 = 3: a tail of storage-buffer voxels
  const TransferFunction ref_tf = random_tf(9, 42, -0.1, 1.1), opt_tf = random_tf(n, 43, -0.1, 1.1);
  const FieldMapping rm = make_mapping({0.0, 1.0}, 9), om = make_mapping({3.0, 8.0}, n);
  const FieldMapping bm = make_mapping({3.0, 8.0}, 9);  // the second field onto the reference TF
  Buffer rtf = upload_tf(ctx(), ref_tf, "ref tf"), otf = upload_tf(ctx(), opt_tf, "opt tf");
  auto words = [&](const DeviceField& ref, const DeviceField& opt, uint64_t range_quads, uint32_t workgroup,
                   const FieldMapping& map, const Buffer& tf, const FieldMapping* before) {
    const VoxelLossKernel kernel(ctx(), range_quads, workgroup);
    const size_t slots = (before ? 2 : 1) * TFM_LOSS_SLOTS;
    Buffer accum(ctx(), slots * 8, MemoryUsage::Device, "loss words");
    CommandBatch batch(ctx());
    batch.fill(accum, 0u);
    batch.barrier();
    kernel.record(batch, ref, opt, rm, map, rtf, tf, accum, before);
    batch.submit_and_wait();
    std::vector<uint32_t> w(slots * 2);
    readback(ctx(), accum, w.data(), w.size() * sizeof(uint32_t));
    return w;
  };
  const DeviceField ref(ctx(), p.ref, "ref"), opt(ctx(), p.opt, "opt");
  const std::vector<uint32_t> after = words(ref, opt, 0, 0, om, otf, nullptr);
  const std::vector<uint32_t> before = words(ref, opt, 0, 0, bm, rtf, nullptr);
  std::vector<uint32_t> both = after;
  both.insert(both.end(), before.begin(), before.end());
  EXPECT_EQ(words(ref, opt, 0, 0, om, otf, &bm), both);
  const DeviceField ref_chunks(ctx(), p.ref, "ref", 4096), opt_chunks(ctx(), p.opt, "opt", 4096);
  for (uint32_t workgroup : {ctx().subgroup_size(), 2 * ctx().subgroup_size(), uint32_t(TFM_VOXEL_WORKGROUP)})
    for (uint64_t range_quads : {uint64_t(0), uint64_t(64), uint64_t(704)}) {
      SCOPED_TRACE("workgroup " + std::to_string(workgroup) + ", ranges of " + std::to_string(range_quads) + " quads");
      EXPECT_EQ(words(ref, opt, range_quads, workgroup, om, otf, &bm), both);
      EXPECT_EQ(words(ref_chunks, opt_chunks, range_quads, workgroup, om, otf, &bm), both);
    }
  // voxel_losses_gpu is the same pass, voxel_loss_gpu the single one.
  const VoxelLosses l = voxel_losses_gpu(ctx(), ref, opt, rm, bm, om, rtf, otf);
  const VoxelLoss single = voxel_loss_gpu(ctx(), ref, opt, rm, om, rtf, otf);
  EXPECT_EQ(l.after.squared, single.squared);
  EXPECT_EQ(l.after.absolute, single.absolute);
  EXPECT_EQ(l.after.voxels, single.voxels);
  // A kernel prepared on another thread (run_optimize compiles it during the solve) gives the
  // same bits.
  {
    const VoxelLossKernel prepared(ctx());
    std::thread([&] { prepared.prepare(/*with_before=*/true); }).join();
    const VoxelLosses lp = voxel_losses_gpu(ctx(), ref, opt, rm, bm, om, rtf, otf, nullptr, &prepared);
    EXPECT_EQ(lp.after.squared, l.after.squared);
    EXPECT_EQ(lp.after.absolute, l.after.absolute);
    EXPECT_EQ(lp.before.squared, l.before.squared);
    EXPECT_EQ(lp.before.absolute, l.before.absolute);
    EXPECT_EQ(lp.before.voxels, l.before.voxels);
  }
  // Against the double loop: d of floats in [-0.1, 1.1] moves by < 6e-7, d^2 by < 2e-6, and
  // each term is truncated to 2^-32.
  const std::vector<float> r = ref_tf.as_floats(), o = opt_tf.as_floats();
  std::array<double, 4> sq_after{}, abs_after{}, sq_before{}, abs_before{};
  uint64_t counted = 0;
  for (size_t i = 0; i < p.ref.size(); ++i) {
    uint32_t jr, jo, jb;
    float wr, wo, wb;
    if (!tf_coordinate(p.ref[i], rm, jr, wr) || !tf_coordinate(p.opt[i], om, jo, wo)) continue;
    tf_coordinate(p.opt[i], bm, jb, wb);
    ++counted;
    for (int c = 0; c < 4; ++c) {
      const double b = std::clamp((1.0 - wr) * r[4 * jr + c] + double(wr) * r[4 * (jr + 1) + c], 0.0, 1.0);
      const double va = std::clamp((1.0 - wo) * o[4 * jo + c] + double(wo) * o[4 * (jo + 1) + c], 0.0, 1.0);
      const double vb = std::clamp((1.0 - wb) * r[4 * jb + c] + double(wb) * r[4 * (jb + 1) + c], 0.0, 1.0);
      sq_after[c] += (va - b) * (va - b), abs_after[c] += std::abs(va - b);
      sq_before[c] += (vb - b) * (vb - b), abs_before[c] += std::abs(vb - b);
    }
  }
  ASSERT_EQ(l.after.voxels, counted);
  ASSERT_EQ(l.before.voxels, counted);
  const double term = std::ldexp(1.0, -32);
  for (int c = 0; c < 4; ++c) {
    EXPECT_NEAR(l.after.squared[c], sq_after[c], double(counted) * (2e-6 + term)) << "channel " << c;
    EXPECT_NEAR(l.after.absolute[c], abs_after[c], double(counted) * (1e-6 + term)) << "channel " << c;
    EXPECT_NEAR(l.before.squared[c], sq_before[c], double(counted) * (2e-6 + term)) << "channel " << c;
    EXPECT_NEAR(l.before.absolute[c], abs_before[c], double(counted) * (1e-6 + term)) << "channel " << c;
  }
  const FieldMapping wrong = make_mapping({3.0, 8.0}, 5);  // not the reference TF's size
  EXPECT_THROW(voxel_losses_gpu(ctx(), ref, opt, rm, wrong, om, rtf, otf), std::invalid_argument);
  if (ctx().subgroup_size() > 1) EXPECT_THROW(VoxelLossKernel(ctx(), 0, ctx().subgroup_size() + 1), std::invalid_argument);
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
