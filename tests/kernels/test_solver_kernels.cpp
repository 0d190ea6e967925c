// The matrix-free solver kernels against double-precision CPU references: sparse_prepare
// (coordinates, b), sparse_gather (S x, ||S x||^2) and sparse_scatter (S^T r, plain and with the
// CGLS residual update) on awkward sizes with NaNs, split chunks, every reduction mode and atomic
// width, and bit-identical results across runs, paths, range splits and workgroup counts and sizes.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <utility>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "field_mapping.h"
#include "transfer_function.h"
#include "commands.h"
#include "gpu_voxel_ops.h"
#include "sparse_ops.h"
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

// Sizes: 1, 13, 127, one past a workgroup, one past a workgroup's 64-voxel-per-invocation span.
const size_t kSizes[] = {1, 13, 127, TFM_VOXEL_WORKGROUP + 1, TFM_VOXEL_WORKGROUP * 64 + 1};

TEST_F(SolverKernels, PrepareMatchesCpuCoordinatesAndColours) {
  for (size_t voxels : kSizes) {
    SCOPED_TRACE("voxels " + std::to_string(voxels));
    const Case c = make_case(voxels, 7, 11);
    run_prepare(c, voxels > 100 ? 100 : 0, voxels > 100 ? 50 : 0);
    const std::vector<float> coords = vectors_->read_coords(ctx());
    const std::vector<float> rgba = vectors_->read_rgba(ctx());
    for (size_t i = 0; i < voxels; ++i) {
      uint32_t j;
      float w;
      double b[4];
      if (!reference_voxel(c, i, j, w, b)) {
        ASSERT_EQ(coords[i], float(TFM_NO_DATA)) << "voxel " << i;
        continue;
      }
      // The coordinate is exactly j + w: the kernel splits it back bit-identically.
      ASSERT_EQ(coords[i], float(j) + w) << "voxel " << i;
      // b: two float products and a sum, < 3 * 2^-24 relative; 1e-6 absolute covers it for b <= 1.
      for (int ch = 0; ch < 4; ++ch) ASSERT_NEAR(rgba[4 * i + ch], b[ch], 1e-6) << "voxel " << i << " channel " << ch;
    }
  }
}

TEST_F(SolverKernels, GatherMatchesCpuProductAndNorm) {
  const uint32_t n = 7;
  for (size_t voxels : kSizes) {
    SCOPED_TRACE("voxels " + std::to_string(voxels));
    const Case c = make_case(voxels, n, 21);
    run_prepare(c, voxels > 100 ? 200 : 0, voxels > 100 ? 40 : 0);
    const std::vector<float> x = random_vec4s(n, 5, -0.5f, 1.5f);
    Buffer xb = make_buffer<float>(ctx(), x, "x");
    Buffer norm(ctx(), TFM_GATHER_NORM_SLOTS * 8, MemoryUsage::Device, "norm");
    fill(ctx(), norm, 0u);
    SparseGatherKernel gather(ctx(), true, true);
    CommandBatch batch(ctx());
    gather.record(batch, *vectors_, n, xb, norm);
    batch.submit_and_wait();
    const std::vector<float> q = vectors_->read_rgba(ctx());
    std::vector<uint32_t> words(TFM_GATHER_NORM_SLOTS * 2);
    readback(ctx(), norm, words.data(), words.size() * 4);
    const std::vector<double> norm2 = decode_fixed_point(words);
    double ref_norm2[4] = {0, 0, 0, 0};
    for (size_t i = 0; i < voxels; ++i) {
      uint32_t j;
      float w;
      double b[4];
      const bool has = reference_voxel(c, i, j, w, b);
      for (int ch = 0; ch < 4; ++ch) {
        const double expected = has ? (1.0 - double(w)) * x[4 * j + ch] + double(w) * x[4 * (j + 1) + ch] : 0.0;
        // Two float products and a sum of values below 1.5: a few ulps, < 1e-6.
        ASSERT_NEAR(q[4 * i + ch], expected, 1e-6) << "voxel " << i << " channel " << ch;
        ref_norm2[ch] += expected * expected;
      }
    }
    for (int ch = 0; ch < 4; ++ch) {
      // Per voxel: q^2 rounded in float (q within 1e-6 of exact, |q| < 1.5: < 4e-6) and truncated
      // to 2^-32 when converted to fixed point.
      ASSERT_NEAR(norm2[ch], ref_norm2[ch], double(voxels) * (4e-6 + std::ldexp(1.0, -32))) << "channel " << ch;
    }
  }
}

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

TEST_F(SolverKernels, ScatterMatchesCpuTransposeProduct) {
  const uint32_t n = 9;
  for (const ReductionOptions& path : reduction_paths(ctx(), n)) {
    for (size_t voxels : kSizes) {
      SCOPED_TRACE("voxels " + std::to_string(voxels) + ", " + path_name(path));
      const Case c = make_case(voxels, n, 31);
      run_prepare(c, voxels > 100 ? 300 : 0, voxels > 100 ? 100 : 0);
      // Signed residuals: both accumulators of every slot are exercised.
      const std::vector<float> r = random_vec4s(voxels, 8, -1.0f, 1.0f);
      for (size_t ch = 0; ch < vectors_->chunk_count(); ++ch)
        upload(ctx(), vectors_->rgba(ch), r.data() + 4 * vectors_->chunk_begin(ch), vectors_->chunk_size(ch) * 16);
      const std::vector<double> s = scatter_once(ctx(), *vectors_, n, path);
      std::vector<double> expected(4 * n, 0.0), magnitude(4 * n, 0.0);
      std::vector<uint64_t> terms(4 * n, 0);
      for (size_t i = 0; i < voxels; ++i) {
        uint32_t j;
        float w;
        double b[4];
        if (!reference_voxel(c, i, j, w, b)) continue;
        for (int ch = 0; ch < 4; ++ch) {
          const double lo = (1.0 - double(w)) * r[4 * i + ch], hi = double(w) * r[4 * i + ch];
          expected[4 * j + ch] += lo;
          expected[4 * (j + 1) + ch] += hi;
          magnitude[4 * j + ch] += std::abs(lo);
          magnitude[4 * (j + 1) + ch] += std::abs(hi);
          ++terms[4 * j + ch];
          ++terms[4 * (j + 1) + ch];
        }
      }
      for (size_t k = 0; k < expected.size(); ++k) {
        // Each term: one float product (2^-24 relative), truncated to 2^-32 on its own; the
        // fixed-point total is exact. So |error| <= magnitude 2^-24 + terms 2^-32; 2^-22 leaves
        // room for w and 1 - w (one more rounding each).
        const double tol = magnitude[k] * std::ldexp(1.0, -22) + double(terms[k]) * std::ldexp(1.0, -32) + 1e-12;
        ASSERT_NEAR(s[k], expected[k], tol) << "slot " << k << " (entry " << k / 4 << ", channel " << k % 4 << ")";
      }
    }
  }
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
  // ||q||^2 and S^T b within the bounds of GatherMatchesCpuProductAndNorm and
  // ScatterMatchesCpuTransposeProduct.
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

TEST_F(SolverKernels, ScatterUpdateAppliesResidualStep) {
  const uint32_t n = 5;
  const size_t voxels = TFM_VOXEL_WORKGROUP + 1;
  const Case c = make_case(voxels, n, 51);
  const std::vector<float> p = random_vec4s(n, 10, -1.0f, 1.0f);
  Buffer pb = make_buffer<float>(ctx(), p, "p");
  gpu::CglsState st{};
  st.alpha = {0.5f, -0.25f, 2.0f, 0.0f};
  st.running = {1, 1, 1, 1};
  Buffer state = make_buffer<gpu::CglsState>(ctx(), std::span<const gpu::CglsState>(&st, 1), "state");
  Buffer accum(ctx(), signed_accumulator_bytes(n), MemoryUsage::Device, "accum");
  for (const ReductionOptions& path : reduction_paths(ctx(), n)) {
    SCOPED_TRACE(path_name(path));
    run_prepare(c, 0, 64);  // b as the residual, again for each path
    const std::vector<float> b = vectors_->read_rgba(ctx());
    SparseScatterKernel scatter(ctx(), n, true, path);
    CommandBatch batch(ctx());
    batch.fill(accum, 0u);
    batch.barrier();
    scatter.record_update(batch, *vectors_, pb, state, accum);
    batch.submit_and_wait();
    const std::vector<float> r = vectors_->read_rgba(ctx());
    std::vector<uint32_t> words(signed_accumulator_bytes(n) / 4);
    readback(ctx(), accum, words.data(), words.size() * 4);
    const std::vector<double> s = decode_signed_fixed_point(words);
    const double alpha[4] = {0.5, -0.25, 2.0, 0.0};
    std::vector<double> expected(4 * n, 0.0);
    for (size_t i = 0; i < voxels; ++i) {
      uint32_t j;
      float w;
      double bb[4];
      if (!reference_voxel(c, i, j, w, bb)) {
        for (int ch = 0; ch < 4; ++ch) ASSERT_EQ(r[4 * i + ch], b[4 * i + ch]) << "voxel without data " << i;
        continue;
      }
      for (int ch = 0; ch < 4; ++ch) {
        const double sp = (1.0 - double(w)) * p[4 * j + ch] + double(w) * p[4 * (j + 1) + ch];
        const double ri = b[4 * i + ch] - alpha[ch] * sp;
        // Float update of values below ~3: a few ulps.
        ASSERT_NEAR(r[4 * i + ch], ri, 2e-6) << "voxel " << i << " channel " << ch;
        expected[4 * j + ch] += (1.0 - double(w)) * ri;
        expected[4 * (j + 1) + ch] += double(w) * ri;
      }
    }
    // 257 voxels, each term within 2e-6 (r) plus a float product: 257 * 3e-6 bounds the sum.
    for (size_t k = 0; k < expected.size(); ++k) ASSERT_NEAR(s[k], expected[k], 257 * 3e-6) << "slot " << k;
  }
}

}  // namespace
}  // namespace tfm
