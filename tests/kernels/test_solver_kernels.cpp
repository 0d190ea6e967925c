// The matrix-free solver kernels beyond their case table (host/selftest/selftest_sparse.cpp, run
// by test_kernel_cases.cpp: sparse_prepare, sparse_gather and sparse_scatter, plain and with the
// CGLS residual update, against double references on awkward sizes with NaNs, split chunks,
// every reduction mode and atomic width): bit-identical results across runs, paths, range splits
// and workgroup counts and sizes, and a scaled gather that does nothing once every channel stopped.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <utility>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/model/field_mapping.h"
#include "tfmatch/model/transfer_function.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

struct Case {
  std::vector<float> ref, opt;
  TransferFunction ref_tf;
  FieldMapping ref_map, opt_map;
};

// Random fields with NaNs in both, values outside the range (clamped) and on TF nodes.
Case make_case(size_t voxels, uint32_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-0.1f, 1.1f);
  Case c;
  c.ref.resize(voxels);
  c.opt.resize(voxels);
  for (size_t i = 0; i < voxels; ++i) {
    c.ref[i] = u(rng);
    c.opt[i] = 2.0f + 3.0f * u(rng);
    if (i % 5 == 2) c.opt[i] = 2.0f + 3.0f * float(rng() % n) / float(n - 1);
    if (i % 11 == 4) c.ref[i] = NAN;
    if (i % 9 == 7) c.opt[i] = NAN;
  }
  c.ref_tf.rgba.resize(16);
  for (auto& e : c.ref_tf.rgba) e = {u(rng), u(rng), u(rng), u(rng)};  // some outside [0,1]: b is clamped
  c.ref_map = make_mapping({0.0, 1.0}, 16);
  c.opt_map = make_mapping({2.0, 5.0}, n);
  return c;
}

// Double-precision reference of one voxel: its coordinate and b, or false without data.
bool reference_voxel(const Case& c, size_t i, uint32_t& j, float& w, double b[4]) {
  uint32_t jr;
  float wr;
  if (!tf_coordinate(c.ref[i], c.ref_map, jr, wr) || !tf_coordinate(c.opt[i], c.opt_map, j, w)) return false;
  for (int ch = 0; ch < 4; ++ch) {
    const double v = (1.0 - double(wr)) * float(c.ref_tf.rgba[jr][ch]) + double(wr) * float(c.ref_tf.rgba[jr + 1][ch]);
    b[ch] = std::clamp(v, 0.0, 1.0);
  }
  return true;
}

std::vector<float> random_vec4s(size_t count, uint32_t seed, float lo, float hi) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(lo, hi);
  std::vector<float> v(4 * count);
  for (float& x : v) x = u(rng);
  return v;
}

class SolverKernels : public test::GpuTest {
 protected:
  // Fields split into chunks of `field_chunk` voxels, voxel vectors into `vector_chunk`.
  void run_prepare(const Case& c, uint64_t field_chunk, uint64_t vector_chunk) {
    ref_ = std::make_unique<DeviceField>(ctx(), c.ref, "ref", field_chunk);
    opt_ = std::make_unique<DeviceField>(ctx(), c.opt, "opt", field_chunk);
    vectors_ = std::make_unique<VoxelVectors>(ctx(), *ref_, *opt_, vector_chunk);
    Buffer tf = upload_tf(ctx(), c.ref_tf, "ref tf");
    SparsePrepareKernel prepare(ctx());
    CommandBatch batch(ctx());
    prepare.record(batch, *ref_, *opt_, c.ref_map, c.opt_map, tf, *vectors_);
    batch.submit_and_wait();
  }
  std::unique_ptr<DeviceField> ref_, opt_;
  std::unique_ptr<VoxelVectors> vectors_;
};

// Every mode and atomic width the device can run (64-bit only where it has them; shared only
// where 4N slots fit).
std::vector<ReductionOptions> reduction_paths(const Context& ctx, uint32_t n) {
  std::vector<ReductionOptions> paths;
  for (ReductionMode mode : {ReductionMode::RunsShared, ReductionMode::RunsGlobal, ReductionMode::Private})
    for (AtomicWidth width : {AtomicWidth::Bits32, AtomicWidth::Bits64}) {
      if (width == AtomicWidth::Bits64 && !ctx.int64_atomics()) continue;
      if (mode == ReductionMode::Private && width == AtomicWidth::Bits32) continue;  // a 64-bit path only
      if (mode == ReductionMode::RunsShared && !signed_slots_fit_shared(ctx, n)) continue;
      paths.push_back({mode, width});
    }
  return paths;
}

std::string path_name(const ReductionOptions& o) {
  return std::string(reduction_mode_name(o.mode)) + (o.atomics == AtomicWidth::Bits64 ? ", 64-bit" : ", 32-bit") +
         (o.workgroups ? ", " + std::to_string(o.workgroups) + " workgroups" : "");
}

// S^T r of the voxel vectors' RGBA buffer, read back as 4N doubles.
std::vector<double> scatter_once(Context& ctx, VoxelVectors& v, uint32_t n, ReductionOptions options) {
  SparseScatterKernel scatter(ctx, n, false, options);
  Buffer accum(ctx, signed_accumulator_bytes(n), MemoryUsage::Device, "accum");
  CommandBatch batch(ctx);
  batch.fill(accum, 0u);
  batch.barrier();
  scatter.record(batch, v, accum);
  batch.submit_and_wait();
  std::vector<uint32_t> words(signed_accumulator_bytes(n) / 4);
  readback(ctx, accum, words.data(), words.size() * 4);
  return decode_signed_fixed_point(words);
}

TEST_F(SolverKernels, ScatterIsBitIdenticalAcrossRunsAndPaths) {
  const uint32_t n = 64;
  const size_t voxels = 20000;
  const Case c = make_case(voxels, n, 41);
  run_prepare(c, 0, 0);  // b as the residual: positive values
  const std::vector<float> r = random_vec4s(voxels, 9, -1.0f, 1.0f);
  upload(ctx(), vectors_->rgba(0), r.data(), r.size() * 4);
  const std::vector<double> first = scatter_once(ctx(), *vectors_, n, {});
  const std::vector<double> second = scatter_once(ctx(), *vectors_, n, {});
  // Integer sums of terms converted one by one are associative: the same bits whatever the
  // order, the mode, the atomic width or the number of workgroups.
  ASSERT_EQ(first, second);
  for (ReductionOptions path : reduction_paths(ctx(), n))
    for (uint32_t groups : {0u, 1u, 7u}) {
      path.workgroups = groups;
      ASSERT_EQ(first, scatter_once(ctx(), *vectors_, n, path)) << path_name(path);
    }
}

// Prepare, gather and scatter read their voxels in ranges of quads (texel views) in workgroups of
// any whole number of subgroups: every range split, workgroup size and chunking gives the same
// bits. Vector chunks of 750 voxels inside field chunks of 6000 start off every texel alignment
// above 8 bytes (the prepare's views start below them); 20011 voxels leave a tail of 3.
TEST_F(SolverKernels, SameBitsForEveryRangeSplitWorkgroupSizeAndChunking) {
  const uint32_t n = 23;
  const size_t voxels = 20011;
  const Case c = make_case(voxels, n, 61);
  Buffer tf = upload_tf(ctx(), c.ref_tf, "ref tf");
  const std::vector<float> x = random_vec4s(n, 62, -0.5f, 1.5f);
  Buffer xb = make_buffer<float>(ctx(), x, "x");
  struct Bits {
    std::vector<float> coords, b, q;
    std::vector<uint32_t> norm, scatter;
  };
  auto words = [&](const Buffer& buf, size_t count) {
    std::vector<uint32_t> w(count);
    readback(ctx(), buf, w.data(), count * 4);
    return w;
  };
  auto run = [&](uint64_t field_chunk, uint64_t vector_chunk, uint64_t range_quads, uint32_t workgroup) {
    const DeviceField ref(ctx(), c.ref, "ref", field_chunk), opt(ctx(), c.opt, "opt", field_chunk);
    VoxelVectors v(ctx(), ref, opt, vector_chunk);
    Buffer norm(ctx(), TFM_GATHER_NORM_SLOTS * 8, MemoryUsage::Device, "norm");
    Buffer accum(ctx(), signed_accumulator_bytes(n), MemoryUsage::Device, "accum");
    const SparsePrepareKernel prepare(ctx(), range_quads, workgroup);
    const SparseScatterKernel scatter(ctx(), n, false, {}, range_quads);
    const SparseGatherKernel gather(ctx(), true, true, false, range_quads, workgroup);
    Bits out;
    CommandBatch batch(ctx());
    prepare.record(batch, ref, opt, c.ref_map, c.opt_map, tf, v);
    batch.fill(accum, 0u);
    batch.fill(norm, 0u);
    batch.barrier();
    scatter.record(batch, v, accum);  // S^T b
    batch.submit_and_wait();
    out.coords = v.read_coords(ctx());
    out.b = v.read_rgba(ctx());
    out.scatter = words(accum, signed_accumulator_bytes(n) / 4);
    CommandBatch batch2(ctx());
    gather.record(batch2, v, n, xb, norm);  // q = S x over b
    batch2.submit_and_wait();
    out.q = v.read_rgba(ctx());
    out.norm = words(norm, TFM_GATHER_NORM_SLOTS * 2);
    return out;
  };
  auto same = [](const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
  };
  const Bits base = run(0, 0, 0, 0);
  for (auto [field_chunk, vector_chunk] : {std::pair<uint64_t, uint64_t>{0, 0}, {6000, 750}, {8192, 4096}})
    for (uint64_t range_quads : {uint64_t(0), uint64_t(64), uint64_t(704)})
      for (uint32_t workgroup : {ctx().subgroup_size(), 2 * ctx().subgroup_size(), uint32_t(TFM_VOXEL_WORKGROUP)}) {
        SCOPED_TRACE("field chunks " + std::to_string(field_chunk) + ", vector chunks " + std::to_string(vector_chunk) +
                     ", ranges of " + std::to_string(range_quads) + " quads, workgroup " + std::to_string(workgroup));
        const Bits b = run(field_chunk, vector_chunk, range_quads, workgroup);
        EXPECT_TRUE(same(b.coords, base.coords));
        EXPECT_TRUE(same(b.b, base.b));
        EXPECT_TRUE(same(b.q, base.q));
        EXPECT_EQ(b.norm, base.norm);
        EXPECT_EQ(b.scatter, base.scatter);
      }
  // The base run against the CPU: coordinates exactly, b and q within a few float roundings,
  // ||q||^2 and S^T b within the bounds of the table's gather and scatter cases
  // (host/selftest/selftest_sparse.cpp).
  double norm2[4] = {0, 0, 0, 0};
  std::vector<double> stb(4 * n, 0.0), magnitude(4 * n, 0.0);
  uint64_t counted = 0;
  for (size_t i = 0; i < voxels; ++i) {
    uint32_t j;
    float w;
    double b[4];
    if (!reference_voxel(c, i, j, w, b)) {
      ASSERT_EQ(base.coords[i], float(TFM_NO_DATA)) << "voxel " << i;
      for (int ch = 0; ch < 4; ++ch) ASSERT_EQ(base.q[4 * i + ch], 0.0f) << "voxel " << i;
      continue;
    }
    ++counted;
    ASSERT_EQ(base.coords[i], float(j) + w) << "voxel " << i;
    for (int ch = 0; ch < 4; ++ch) {
      const double q = (1.0 - double(w)) * x[4 * j + ch] + double(w) * x[4 * (j + 1) + ch];
      ASSERT_NEAR(base.b[4 * i + ch], b[ch], 1e-6) << "voxel " << i;
      ASSERT_NEAR(base.q[4 * i + ch], q, 1e-6) << "voxel " << i;
      norm2[ch] += q * q;
      const double r = base.b[4 * i + ch];  // the residual the scatter read
      stb[4 * j + ch] += (1.0 - double(w)) * r;
      stb[4 * (j + 1) + ch] += double(w) * r;
      magnitude[4 * j + ch] += (1.0 - double(w)) * r;
      magnitude[4 * (j + 1) + ch] += double(w) * r;
    }
  }
  const std::vector<double> norm = decode_fixed_point(base.norm);
  for (int ch = 0; ch < 4; ++ch)
    EXPECT_NEAR(norm[ch], norm2[ch], double(counted) * (4e-6 + std::ldexp(1.0, -32))) << "channel " << ch;
  const std::vector<double> s = decode_signed_fixed_point(base.scatter);
  for (size_t k = 0; k < stb.size(); ++k)
    EXPECT_NEAR(s[k], stb[k], magnitude[k] * std::ldexp(1.0, -22) + double(2 * counted) * std::ldexp(1.0, -32) + 1e-12)
        << "slot " << k;
  EXPECT_THROW(SparseGatherKernel(ctx(), true, true, false, 100), std::invalid_argument);  // not a multiple of 64
  EXPECT_THROW(SparsePrepareKernel(ctx(), 0, ctx().subgroup_size() + 1), std::invalid_argument);
  EXPECT_THROW(SparseScatterKernel(ctx(), n, false, {}, uint64_t(ctx().limits().maxTexelBufferElements) / 4 + 64),
               std::invalid_argument);  // r is a texel per voxel
}

// A scaled gather (CGLS) recorded after every channel stopped adds nothing and writes nothing.
TEST_F(SolverKernels, ScaledGatherDoesNothingOnceEveryChannelStopped) {
  const uint32_t n = 7;
  const Case c = make_case(5000, n, 71);
  run_prepare(c, 0, 0);
  const std::vector<float> b = vectors_->read_rgba(ctx());
  Buffer xb = make_buffer<float>(ctx(), random_vec4s(n, 72, -0.5f, 1.5f), "x");
  Buffer norm(ctx(), TFM_GATHER_NORM_SLOTS * 8, MemoryUsage::Device, "norm");
  gpu::CglsState st{};
  st.p_scale = {1, 1, 1, 1};
  for (uint32_t running : {0u, 1u}) {
    SCOPED_TRACE("running " + std::to_string(running));
    st.running = {0, running, 0, 0};
    Buffer state = make_buffer<gpu::CglsState>(ctx(), std::span<const gpu::CglsState>(&st, 1), "state");
    fill(ctx(), norm, 0u);
    const SparseGatherKernel gather(ctx(), true, true, true);
    CommandBatch batch(ctx());
    gather.record(batch, *vectors_, n, xb, norm, &state);
    batch.submit_and_wait();
    std::vector<uint32_t> w(TFM_GATHER_NORM_SLOTS * 2);
    readback(ctx(), norm, w.data(), w.size() * 4);
    const bool untouched = vectors_->read_rgba(ctx()) == b;
    EXPECT_EQ(untouched, running == 0);
    EXPECT_EQ(std::all_of(w.begin(), w.end(), [](uint32_t v) { return v == 0; }), running == 0);
  }
}

}  // namespace
}  // namespace tfm
