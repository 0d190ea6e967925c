// The `cgls` solver: matrix-free, Jacobi-preconditioned CGLS on the GPU, four channels at once.
// Per iteration: ||S p||^2 (sparse_gather), alpha and x (cgls_vectors), r -= alpha S p with
// s = S^T r (sparse_scatter), beta and p (cgls_vectors). Iterations are recorded in batches; the
// stop test runs on the GPU per channel, so a stopped channel's later iterations change nothing.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "cgls_vectors.h"
#include "solver_registry.h"
#include "commands.h"
#include "solver_support.h"
#include "sparse_ops.h"

namespace tfm {
namespace {

// Iterations per submission: the host reads the stop flags once per batch.
constexpr uint32_t kIterationsPerBatch = 4;

SolverOutput solve_with_cgls(VoxelProblem& p, const SolverSettings& settings) {
  const double tolerance = settings.number("tolerance", 1e-6);
  if (!(tolerance > 0.0 && tolerance < 1.0))
    throw std::runtime_error("--tolerance: expected a number in (0, 1), got " + settings.text("tolerance", ""));
  const uint32_t max_iterations = positive_integer(settings, "max-iterations", 1000);
  const uint64_t max_chunk = uint64_t(settings.number("max-chunk-voxels", 0));  // tests force chunking
  Context& ctx = p.ctx;
  const uint32_t n = p.opt_map.tf_size;

  SolverOutput out;
  auto t0 = std::chrono::steady_clock::now();
  JacobiSetup js = jacobi_setup(p, settings);
  VoxelVectors vectors(ctx, p.ref, p.opt, max_chunk);
  Buffer inv_diag = make_buffer<float>(ctx, js.inv_diag, "CGLS inverse diagonal");
  Buffer s_accum(ctx, signed_accumulator_bytes(n), MemoryUsage::Device, "CGLS S^T r accumulators");
  Buffer delta_accum(ctx, TFM_GATHER_NORM_SLOTS * 8, MemoryUsage::Device, "CGLS ||S p||^2 accumulators");
  Buffer x(ctx, uint64_t(n) * 16, MemoryUsage::Device, "CGLS x");
  Buffer dir(ctx, uint64_t(n) * 16, MemoryUsage::Device, "CGLS p");
  Buffer state(ctx, sizeof(gpu::CglsState), MemoryUsage::Device, "CGLS state");
  const SparsePrepareKernel prepare(ctx);
  const SparseGatherKernel gather(ctx, false, true, true);
  const SparseScatterKernel scatter(ctx, n, false);
  const SparseScatterKernel scatter_update(ctx, n, true);
  const CglsVectorsKernel vectors_kernel(ctx);
  const CglsBuffers buffers{&s_accum, &delta_accum, &inv_diag, &x, &dir, &state};
  const float ridge = float(js.reg.ridge), smooth = float(js.reg.smooth), tol = float(tolerance);

  double setup_gpu_ms = js.gpu_ms;
  {
    CommandBatch batch(ctx);
    const uint32_t a = batch.timestamp();
    prepare.record(batch, p.ref, p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer, vectors);
    batch.fill(s_accum, 0u);
    // Coordinates, b and zeroed accumulators are written before the scatter reads them.
    batch.barrier();
    scatter.record(batch, vectors, s_accum);  // s0 = S^T b (ends with a barrier)
    vectors_kernel.record(batch, TFM_CGLS_STAGE_INIT, n, ridge, smooth, tol, buffers);
    const uint32_t b = batch.timestamp();
    batch.submit_and_wait();
    if (setup_gpu_ms >= 0 && batch.elapsed_ms(a, b) >= 0) setup_gpu_ms += batch.elapsed_ms(a, b);
  }
  out.phases.push_back({"setup", ms_since(t0), setup_gpu_ms});

  t0 = std::chrono::steady_clock::now();
  double iterate_gpu_ms = 0.0;
  gpu::CglsState st{};
  readback(ctx, state, &st, sizeof(st));
  uint32_t recorded = 0;
  auto running = [&st] { return st.running.x | st.running.y | st.running.z | st.running.w; };
  while (running() && recorded < max_iterations) {
    const uint32_t count = std::min(kIterationsPerBatch, max_iterations - recorded);
    CommandBatch batch(ctx);
    const uint32_t a = batch.timestamp();
    for (uint32_t k = 0; k < count; ++k) {
      batch.fill(delta_accum, 0u);
      // The zeroed accumulator (and p from the previous direction stage) before the gather.
      batch.barrier();
      gather.record(batch, vectors, n, dir, delta_accum, &state);  // ||S p||^2 (ends with a barrier)
      vectors_kernel.record(batch, TFM_CGLS_STAGE_STEP, n, ridge, smooth, tol, buffers);
      // alpha is written, and the vector stages are done with s, before s is cleared.
      batch.barrier();
      batch.fill(s_accum, 0u);
      batch.barrier();
      scatter_update.record_update(batch, vectors, dir, state, s_accum);  // (ends with a barrier)
      vectors_kernel.record(batch, TFM_CGLS_STAGE_DIRECTION, n, ridge, smooth, tol, buffers);
      // p, x and the state are final before the next iteration reads them.
      batch.barrier();
    }
    const uint32_t b = batch.timestamp();
    batch.submit_and_wait();
    iterate_gpu_ms = batch.elapsed_ms(a, b) >= 0 ? iterate_gpu_ms + batch.elapsed_ms(a, b) : -1.0;
    recorded += count;
    readback(ctx, state, &st, sizeof(st));
  }
  out.phases.push_back({"iterate", ms_since(t0), ctx.timestamps_supported() ? iterate_gpu_ms : -1.0});

  std::vector<float> xs(size_t(n) * 4);
  readback(ctx, x, xs.data(), xs.size() * sizeof(float));
  uint32_t clamped = 0;
  out.tf = tf_from_floats(xs, &clamped);

  const uint32_t iterations[4] = {st.iterations.x, st.iterations.y, st.iterations.z, st.iterations.w};
  const float s2[4] = {st.s_norm2.x, st.s_norm2.y, st.s_norm2.z, st.s_norm2.w};
  const float s02[4] = {st.s0_norm2.x, st.s0_norm2.y, st.s0_norm2.z, st.s0_norm2.w};
  nlohmann::json iters = nlohmann::json::array(), residuals = nlohmann::json::array();
  uint32_t max_iter = 0;
  double worst = 0.0;
  for (int c = 0; c < 4; ++c) {
    const double rel = s02[c] > 0.0f ? std::sqrt(double(s2[c]) / double(s02[c])) : 0.0;
    iters.push_back(iterations[c]);
    residuals.push_back(rel);
    max_iter = std::max(max_iter, iterations[c]);
    worst = std::max(worst, rel);
  }
  out.details["iterations"] = max_iter;
  out.details["iterations_per_channel"] = iters;
  out.details["relative_residual"] = worst;  // ||S^T r - R x|| / ||S^T b||, worst channel
  out.details["relative_residual_per_channel"] = residuals;
  out.details["tolerance"] = tolerance;
  out.details["clamped_values"] = clamped;
  out.details["voxel_chunks"] = vectors.chunk_count();
  out.details["ridge"] = settings.solve.ridge;
  out.details["smooth"] = settings.solve.smooth;
  if (worst > tolerance) {
    std::ostringstream os;
    os << "CGLS stopped at --max-iterations " << max_iterations << " with relative residual " << worst
       << " above --tolerance " << tolerance;
    out.warnings.push_back(os.str());
  }
  return out;
}


}  // namespace
SolverOutput run_cgls_solver(VoxelProblem& p, const SolverSettings& s) { return solve_with_cgls(p, s); }

}  // namespace tfm
