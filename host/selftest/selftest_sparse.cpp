// Self-test cases of the matrix-free solver kernels: sparse_prepare (coordinates, b),
// sparse_gather (S x, ||S x||^2), sparse_scatter (S^T r on the shared-memory and global paths, and
// with the CGLS residual update), and cgls_vectors through one whole CGLS solve against the
// regularized normal equations solved densely in double (Eigen).
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>

#include <Eigen/Dense>
#include <Eigen/Sparse>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/device_cgls.h"
#include "tfmatch/kernels/gpu_voxel_ops.h"
#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/reference/normal_equations_cpu.h"
#include "tfmatch/selftest/selftest_support.h"

namespace tfm::selftest {
namespace {

const FieldRange kOptRange{2.0, 5.0};

// Fields, a reference TF with entries outside [0,1] (b is clamped), their mappings, and the
// device copies with field chunks of `field_chunk` voxels and voxel-vector chunks of
// `vector_chunk` (0: as large as the device allows).
struct Problem {
  FieldPair fields;
  TransferFunction ref_tf;
  std::vector<float> ref_tf_floats;
  FieldMapping ref_map, opt_map;
  std::unique_ptr<DeviceField> ref, opt;
  std::unique_ptr<VoxelVectors> vectors;
  Buffer ref_tf_buffer;

  Problem(Context& ctx, size_t voxels, uint32_t n, uint32_t seed, uint64_t field_chunk, uint64_t vector_chunk)
      : fields(random_pair(voxels, seed, kOptRange, n)),
        ref_tf(random_tf(16, seed + 1, -0.1, 1.1)),
        ref_tf_floats(ref_tf.as_floats()),
        ref_map(make_mapping({0.0, 1.0}, 16)),
        opt_map(make_mapping(kOptRange, n)) {
    ref = std::make_unique<DeviceField>(ctx, fields.ref, "selftest reference", field_chunk);
    opt = std::make_unique<DeviceField>(ctx, fields.opt, "selftest field", field_chunk);
    vectors = std::make_unique<VoxelVectors>(ctx, *ref, *opt, vector_chunk);
    ref_tf_buffer = upload_tf(ctx, ref_tf, "selftest reference TF");
  }
  // Writes coordinates and b of every voxel.
  void prepare(Context& ctx) {
    const SparsePrepareKernel kernel(ctx);
    CommandBatch batch(ctx);
    kernel.record(batch, *ref, *opt, ref_map, opt_map, ref_tf_buffer, *vectors);
    batch.submit_and_wait();
  }
  // The reference of voxel i: its coordinate (j, w) and b, or false without data.
  bool voxel(size_t i, uint32_t& j, float& w, double b[4]) const {
    return classify(ref_tf_floats, ref_map, fields.ref[i], b) && tf_coordinate(fields.opt[i], opt_map, j, w);
  }
  size_t voxels() const { return fields.ref.size(); }
};

struct SparseCase {
  size_t voxels;
  uint64_t field_chunk = 0, vector_chunk = 0;
};

std::string sparse_name(const SparseCase& c) {
  std::string s = voxels_name(c.voxels);
  if (c.field_chunk) s += ", field chunks of " + std::to_string(c.field_chunk);
  if (c.vector_chunk) s += ", vector chunks of " + std::to_string(c.vector_chunk);
  return s;
}

// Coordinates must be exactly j + w (the kernels split them back bit-identically) or
// TFM_NO_DATA; b is two float products and a sum of values <= 1.1: < 3 * 2^-24 * 1.1, so 1e-6.
void prepare(Context& ctx, Check& check, const SparseCase& c) {
  Problem p(ctx, c.voxels, 7, 11, c.field_chunk, c.vector_chunk);
  p.prepare(ctx);
  const std::vector<float> coords = p.vectors->read_coords(ctx), rgba = p.vectors->read_rgba(ctx);
  for (size_t i = 0; i < c.voxels; ++i) {
    uint32_t j;
    float w;
    double b[4];
    if (!p.voxel(i, j, w, b)) {
      check.equal("coordinate (no data) of voxel", i, coords[i], TFM_NO_DATA);
      continue;
    }
    check.equal("coordinate of voxel", i, coords[i], double(float(j) + w));
    for (int ch = 0; ch < 4; ++ch) check.near("b (4i+c)", 4 * i + ch, rgba[4 * i + ch], b[ch], 1e-6);
  }
}

// q = S x: two float products and a sum of values below 1.5, a few ulps: 1e-6. ||q_c||^2 (of
// q / scale with a scale): per voxel q^2 rounded in float (< 4e-6 for |q| < 1.5, relative to
// q^2 when scaled) and truncated to 2^-32 in fixed point.
void gather(Context& ctx, Check& check, const SparseCase& c, float scale) {
  const uint32_t n = 7;
  Problem p(ctx, c.voxels, n, 21, c.field_chunk, c.vector_chunk);
  p.prepare(ctx);
  const std::vector<float> x = random_floats(4 * n, 5, -0.5f, 1.5f);
  Buffer xb = make_buffer<float>(ctx, x, "selftest x");
  Buffer norm(ctx, TFM_GATHER_NORM_SLOTS * 8, MemoryUsage::Device, "selftest norm");
  gpu::CglsState st{};
  st.p_scale = {scale, scale, scale, scale};
  st.running = {1, 1, 1, 1};  // a stopped state makes the scaled gather do nothing
  Buffer state = make_buffer<gpu::CglsState>(ctx, std::span<const gpu::CglsState>(&st, 1), "selftest CGLS state");
  const bool scaled = scale != 1.0f;
  const SparseGatherKernel kernel(ctx, true, true, scaled);
  CommandBatch batch(ctx);
  batch.fill(norm, 0u);
  // The zeroed accumulators before the gather adds to them.
  batch.barrier();
  kernel.record(batch, *p.vectors, n, xb, norm, scaled ? &state : nullptr);
  batch.submit_and_wait();
  const std::vector<float> q = p.vectors->read_rgba(ctx);
  const std::vector<double> norm2 = decode_fixed_point(read_words(ctx, norm, TFM_GATHER_NORM_SLOTS * 2));
  double expected_norm2[4] = {0, 0, 0, 0};
  for (size_t i = 0; i < c.voxels; ++i) {
    uint32_t j = 0;
    float w = 0.0f;
    double b[4];
    const bool has = p.voxel(i, j, w, b);
    for (int ch = 0; ch < 4; ++ch) {
      const double e = has ? (1.0 - double(w)) * x[4 * j + ch] + double(w) * x[4 * (j + 1) + ch] : 0.0;
      check.near("q (4i+c)", 4 * i + ch, q[4 * i + ch], e, 1e-6);
      expected_norm2[ch] += (e / scale) * (e / scale);
    }
  }
  for (int ch = 0; ch < 4; ++ch)
    check.near("||q||^2, channel", ch, norm2[ch], expected_norm2[ch],
               double(c.voxels) * (4e-6 + std::ldexp(1.0, -32)) + 1e-12);
}

// s = S^T r into signed fixed-point slots. Each term is one float product (2^-24 relative; 2^-22
// with the roundings of w and 1 - w), truncated to 2^-32 on its own; the fixed-point total is
// exact. So |error| <= magnitude * 2^-22 + terms * 2^-32 (tests/kernels/test_solver_kernels.cpp).
void scatter(Context& ctx, Check& check, const SparseCase& c, const ReductionOptions& path) {
  const uint32_t n = 9;
  const std::string missing = reduction_unavailable(ctx, path, n, signed_accumulator_bytes(n));
  if (!missing.empty()) return check.skip(missing);
  Problem p(ctx, c.voxels, n, 31, c.field_chunk, c.vector_chunk);
  p.prepare(ctx);
  // Signed residuals: both halves of every slot are exercised.
  const std::vector<float> r = random_floats(4 * c.voxels, 8, -1.0f, 1.0f);
  VoxelVectors& v = *p.vectors;
  for (size_t k = 0; k < v.chunk_count(); ++k)
    upload(ctx, v.rgba(k), r.data() + 4 * v.chunk_begin(k), v.chunk_size(k) * 16);
  const SparseScatterKernel kernel(ctx, n, false, path);
  check.require(path.mode == ReductionMode::Auto || kernel.mode() == path.mode, "the kernel did not take the requested path");
  Buffer accum(ctx, signed_accumulator_bytes(n), MemoryUsage::Device, "selftest S^T r");
  CommandBatch batch(ctx);
  batch.fill(accum, 0u);
  // The zeroed accumulators before the scatter adds to them.
  batch.barrier();
  kernel.record(batch, v, accum);
  batch.submit_and_wait();
  const std::vector<double> s = decode_signed_fixed_point(read_words(ctx, accum, signed_accumulator_bytes(n) / 4));
  std::vector<double> expected(4 * n, 0.0), magnitude(4 * n, 0.0), terms(4 * n, 0.0);
  for (size_t i = 0; i < c.voxels; ++i) {
    uint32_t j;
    float w;
    double b[4];
    if (!p.voxel(i, j, w, b)) continue;
    for (int ch = 0; ch < 4; ++ch) {
      const double lo = (1.0 - double(w)) * r[4 * i + ch], hi = double(w) * r[4 * i + ch];
      expected[4 * j + ch] += lo;
      expected[4 * (j + 1) + ch] += hi;
      magnitude[4 * j + ch] += std::abs(lo);
      magnitude[4 * (j + 1) + ch] += std::abs(hi);
      terms[4 * j + ch] += 1;
      terms[4 * (j + 1) + ch] += 1;
    }
  }
  for (size_t k = 0; k < expected.size(); ++k)
    check.near("S^T r slot (4j+c)", k, s[k], expected[k],
               magnitude[k] * std::ldexp(1.0, -22) + terms[k] * std::ldexp(1.0, -32) + 1e-12);
}

// The CGLS residual update r -= alpha (S p) before s = S^T r: r is a float update of values
// below ~3 (a few ulps: 2e-6); each slot then sums terms within 2e-6 plus one float product
// (3e-6 per term), as tests/kernels/test_solver_kernels.cpp bounds it.
void scatter_update(Context& ctx, Check& check, const SparseCase& c, const ReductionOptions& path) {
  const uint32_t n = 9;
  const std::string missing = reduction_unavailable(ctx, path, n, signed_accumulator_bytes(n));
  if (!missing.empty()) return check.skip(missing);
  Problem p(ctx, c.voxels, n, 51, c.field_chunk, c.vector_chunk);
  p.prepare(ctx);
  const std::vector<float> b = p.vectors->read_rgba(ctx);
  const std::vector<float> dir = random_floats(4 * n, 10, -1.0f, 1.0f);
  Buffer pb = make_buffer<float>(ctx, dir, "selftest p");
  gpu::CglsState st{};
  st.alpha = {0.5f, -0.25f, 2.0f, 0.0f};
  st.running = {1, 1, 1, 1};
  Buffer state = make_buffer<gpu::CglsState>(ctx, std::span<const gpu::CglsState>(&st, 1), "selftest CGLS state");
  Buffer accum(ctx, signed_accumulator_bytes(n), MemoryUsage::Device, "selftest S^T r");
  const SparseScatterKernel kernel(ctx, n, true, path);
  CommandBatch batch(ctx);
  batch.fill(accum, 0u);
  // The zeroed accumulators before the scatter adds to them.
  batch.barrier();
  kernel.record_update(batch, *p.vectors, pb, state, accum);
  batch.submit_and_wait();
  const std::vector<float> r = p.vectors->read_rgba(ctx);
  const std::vector<double> s = decode_signed_fixed_point(read_words(ctx, accum, signed_accumulator_bytes(n) / 4));
  const double alpha[4] = {0.5, -0.25, 2.0, 0.0};
  std::vector<double> expected(4 * n, 0.0), terms(4 * n, 0.0);
  for (size_t i = 0; i < c.voxels; ++i) {
    uint32_t j;
    float w;
    double bb[4];
    if (!p.voxel(i, j, w, bb)) {  // a voxel without data keeps its residual
      for (int ch = 0; ch < 4; ++ch) check.equal("r without data (4i+c)", 4 * i + ch, r[4 * i + ch], b[4 * i + ch]);
      continue;
    }
    for (int ch = 0; ch < 4; ++ch) {
      const double sp = (1.0 - double(w)) * dir[4 * j + ch] + double(w) * dir[4 * (j + 1) + ch];
      const double ri = b[4 * i + ch] - alpha[ch] * sp;
      check.near("updated r (4i+c)", 4 * i + ch, r[4 * i + ch], ri, 2e-6);
      expected[4 * j + ch] += (1.0 - double(w)) * ri;
      expected[4 * (j + 1) + ch] += double(w) * ri;
      terms[4 * j + ch] += 1;
      terms[4 * (j + 1) + ch] += 1;
    }
  }
  for (size_t k = 0; k < expected.size(); ++k)
    check.near("S^T r slot (4j+c)", k, s[k], expected[k], terms[k] * 3e-6 + 1e-12);
}

struct CglsCase {
  size_t voxels;
  uint32_t tf_size;
  uint64_t field_chunk = 0, vector_chunk = 0;
  double smooth = 0.05;     // relative to the mean diagonal of M (the ridge is 0.1)
  bool bidiagonal = false;  // precondition with diag(M) + R (L D L^T) instead of diag(M + R)
};

// One preconditioned CGLS solve on the device (sparse_prepare, sparse_gather with the scaled norm,
// sparse_scatter with and without the residual update, and the three cgls_vectors stages, as
// kernels/device_cgls.h records them for the `cgls` solver) against (M + R) x = S^T b solved
// densely in double from the CPU assembly. R = ridge I + smooth D^T D. Jacobi (diag(M + R)) with
// weights 10% and 5% of the mean diagonal keeps the scaled condition number small; diag(M) + R,
// factored here by its own L D L^T, keeps it as small under smoothing 1000 times the data. So
// (tests/host/solvers/test_solver_cgls.cpp): with the stop test at 1e-6, |x - x*| <~ cond * 1e-6
// |x*| plus float iterates' ~1e-6; 1e-4 max(1, |x*|) bounds both with margin. The bidiagonal
// cases must also converge in at most min(N, 32) iterations (they take 2 to 6; Jacobi needs
// hundreds at that smoothing), which also ends a broken substitution quickly.
void cgls(Context& ctx, Check& check, const CglsCase& c) {
  const uint32_t n = c.tf_size;
  Problem p(ctx, c.voxels, n, 41, c.field_chunk, c.vector_chunk);
  const NormalEquations eq =
      assemble_normal_equations_cpu(p.fields.ref, p.fields.opt, p.ref_map, p.opt_map, p.ref_tf);
  check.require(eq.voxels > 0, "no voxel has data in both fields");
  const double mean_diag = double(eq.voxels) / n;  // sum of M's rows is the voxel count
  const float ridge = float(0.1 * mean_diag), smooth = float(c.smooth * mean_diag);
  // M + R, tridiagonal: its diagonal, and its off-diagonal for the exact solution.
  std::vector<double> h_diag(n);
  std::vector<Eigen::Triplet<double>> h_terms;
  for (uint32_t j = 0; j < n; ++j) {
    h_diag[j] = eq.diag[j] + double(ridge) + double(smooth) * ((j > 0) + (j + 1 < n));
    h_terms.emplace_back(j, j, h_diag[j]);
    if (j + 1 < n) {
      h_terms.emplace_back(j, j + 1, eq.off[j] - double(smooth));
      h_terms.emplace_back(j + 1, j, eq.off[j] - double(smooth));
    }
  }
  CglsFactors factors;
  factors.inv_pivot.resize(n);
  // L D L^T of diag(h) with R's off-diagonal -smooth, by hand: the self-test does not link the
  // solvers (tridiagonal.h's factor_positive_definite), and its own factors keep it independent.
  if (c.bidiagonal) {
    double pivot = h_diag[0];
    factors.inv_pivot[0] = float(1.0 / pivot);
    for (uint32_t j = 1; j < n; ++j) {
      const double l = -double(smooth) / pivot;
      pivot = h_diag[j] + l * double(smooth);
      factors.lower.push_back(float(l));
      factors.inv_pivot[j] = float(1.0 / pivot);
    }
  } else {
    for (uint32_t j = 0; j < n; ++j) factors.inv_pivot[j] = float(1.0 / h_diag[j]);
  }
  // Sparse L D L^T (Eigen's), so the exact solution costs O(N) also where N is in the tens of
  // thousands.
  Eigen::SparseMatrix<double> h(n, n);
  h.setFromTriplets(h_terms.begin(), h_terms.end());
  const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> h_ldlt(h);
  check.require(h_ldlt.info() == Eigen::Success, "M + R is not positive definite");
  const Eigen::Matrix<double, Eigen::Dynamic, 4> exact = h_ldlt.solve(eq.rhs);

  VoxelVectors& vectors = *p.vectors;
  const SparsePrepareKernel prepare_kernel(ctx);
  DeviceCgls device(ctx, n, factors, {ridge, smooth, 1e-6f});
  {
    CommandBatch batch(ctx);
    prepare_kernel.record(batch, *p.ref, *p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer, vectors);
    device.record_start(batch, vectors);
    batch.submit_and_wait();
  }
  gpu::CglsState st = device.read_state(ctx);
  auto running = [&st] { return st.running.x | st.running.y | st.running.z | st.running.w; };
  const uint32_t bidiagonal_iterations = std::min(n, 32u);
  const uint32_t max_iterations = c.bidiagonal ? bidiagonal_iterations + 4 : 4 * n + 20;
  for (uint32_t done = 0; running() && done < max_iterations; done += 4) {
    CommandBatch batch(ctx);
    for (int k = 0; k < 4; ++k) device.record_iteration(batch, vectors);
    batch.submit_and_wait();
    st = device.read_state(ctx);
  }
  if (c.bidiagonal) {
    const uint32_t iterations[4] = {st.iterations.x, st.iterations.y, st.iterations.z, st.iterations.w};
    for (uint32_t ch = 0; ch < 4; ++ch)
      check.require(iterations[ch] <= bidiagonal_iterations,
                    "channel " + std::to_string(ch) + " took " + std::to_string(iterations[ch]) +
                        " iterations, more than " + std::to_string(bidiagonal_iterations));
  }
  // A run that stops at the iteration cap without meeting its stop test is judged by x alone.
  const std::vector<float> xs = device.read_x(ctx);
  const double bound = 1e-4 * std::max(1.0, exact.cwiseAbs().maxCoeff());
  for (uint32_t j = 0; j < n; ++j)
    for (int ch = 0; ch < 4; ++ch) check.near("x (4j+c)", 4 * j + ch, xs[4 * j + ch], exact(j, ch), bound);
}

}  // namespace

void add_sparse_cases(CaseList& cases) {
  const size_t past_group = TFM_VOXEL_WORKGROUP + 1;
  // One past the span of one subgroup's segment on a 32-wide subgroup (4 voxels a quad).
  const size_t past_span = size_t(32) * TFM_REDUCE_SEGMENT_STEPS * 4 + 1;
  // Also one past a workgroup's 64-voxel-per-invocation span, and a size off every quad and
  // segment, in small chunks.
  const size_t past_lanes = size_t(TFM_VOXEL_WORKGROUP) * 64 + 1;
  const SparseCase quick_sizes[] = {{1},        {13},       {127, 100, 50},         {past_group}, {past_span},
                                    {1000, 300, 100}, {past_lanes, 200, 40}};
  const SparseCase full_sizes[] = {{100003}, {100003, 32768, 8192}};
  auto add_all = [&](const char* kernel, const char* wrapper, const std::string& suffix, auto body) {
    for (const SparseCase& c : quick_sizes)
      cases.push_back({kernel, wrapper, sparse_name(c) + suffix, true, TFM_VOXEL_WORKGROUP,
                       [c, body](Context& ctx, Check& check) { body(ctx, check, c); }});
    for (const SparseCase& c : full_sizes)
      cases.push_back({kernel, wrapper, sparse_name(c) + suffix, false, TFM_VOXEL_WORKGROUP,
                       [c, body](Context& ctx, Check& check) { body(ctx, check, c); }});
  };
  add_all("sparse_prepare", "SparsePrepareKernel", "", prepare);
  add_all("sparse_gather", "SparseGatherKernel", "",
          [](Context& ctx, Check& check, const SparseCase& c) { gather(ctx, check, c, 1.0f); });
  cases.push_back({"sparse_gather", "SparseGatherKernel", sparse_name({past_group}) + ", norm scaled by 1/4", true,
                   TFM_VOXEL_WORKGROUP,
                   [past_group](Context& ctx, Check& check) { gather(ctx, check, {past_group}, 4.0f); }});
  add_all("sparse_scatter", "SparseScatterKernel", "",
          [](Context& ctx, Check& check, const SparseCase& c) { scatter(ctx, check, c, {}); });
  for (const ReductionOptions& path : reduction_paths())
    for (const SparseCase& c : {SparseCase{1}, SparseCase{13}, SparseCase{127, 300, 100}, SparseCase{past_group, 300, 100},
                                SparseCase{1000, 300, 100}, SparseCase{past_lanes, 300, 100}, SparseCase{100003}})
      cases.push_back({"sparse_scatter", "SparseScatterKernel", sparse_name(c) + reduction_name(path),
                       c.voxels < 10000, TFM_VOXEL_WORKGROUP,
                       [c, path](Context& ctx, Check& check) { scatter(ctx, check, c, path); }});
  auto add_update = [&](const SparseCase& c, const ReductionOptions& path) {
    cases.push_back({"sparse_scatter", "SparseScatterKernel",
                     sparse_name(c) + ", CGLS residual update" + reduction_name(path), true, TFM_VOXEL_WORKGROUP,
                     [c, path](Context& ctx, Check& check) { scatter_update(ctx, check, c, path); }});
  };
  add_update({past_group, 0, 64}, {});
  add_update({1000, 300, 100}, {});
  for (const ReductionOptions& path : reduction_paths()) add_update({past_group, 0, 64}, path);

  auto add_cgls = [&](const CglsCase& c, bool quick) {
    std::string name = voxels_name(c.voxels) + ", N=" + std::to_string(c.tf_size) + ", regularized solve";
    if (c.bidiagonal) name += ", smoothing " + std::to_string(int(c.smooth)) + "x inverted by L D L^T";
    if (c.field_chunk) name += ", field chunks of " + std::to_string(c.field_chunk);
    if (c.vector_chunk) name += ", vector chunks of " + std::to_string(c.vector_chunk);
    cases.push_back({"cgls_vectors", "CglsVectorsKernel", name, quick, TFM_VECTOR_WORKGROUP,
                     [c](Context& ctx, Check& check) { cgls(ctx, check, c); }});
  };
  // The quick cases share N with the scatter cases: pipelines specialized for N compile once.
  add_cgls({13, 9}, true);
  add_cgls({past_group, 9}, true);
  add_cgls({5000, 9, 1024, 256}, true);
  add_cgls({100003, 64, 32768, 8192}, false);
  // More entries than the vector kernel's 256 invocations: each loops over two blocks.
  add_cgls({100003, 300}, false);
  // Smoothing 1000 times the data's diagonal, preconditioned by diag(M) + R: the substitution
  // sweeps, and convergence in at most N iterations. One N shared with gather and scatter cases.
  add_cgls({5000, 64, 0, 0, 1000.0, true}, true);
  add_cgls({100003, 300, 32768, 8192, 1000.0, true}, false);
  // The substitution's segments: fewer entries than invocations (most segments empty), and more
  // than one invocation could sweep alone on lavapipe (65535 loop iterations in all), N odd.
  add_cgls({past_group, 9, 0, 0, 1000.0, true}, true);
  add_cgls({100003, 40009, 0, 0, 10.0, true}, true);
}

}  // namespace tfm::selftest
