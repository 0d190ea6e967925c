// The `cgls` solver: matrix-free, Jacobi-preconditioned CGLS on the GPU, four channels at once.
// Per iteration: ||S p||^2 (sparse_gather), alpha and x (cgls_vectors), r -= alpha S p with
// s = S^T r (sparse_scatter), beta and p (cgls_vectors). Iterations are recorded in batches; the
// stop test runs on the GPU per channel, so a stopped channel's later iterations change nothing.
#include "solver_cgls.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "cancellation.h"
#include "cgls_vectors.h"
#include "commands.h"
#include "parameter_names.h"
#include "solver_support.h"
#include "sparse_ops.h"

namespace tfm {
namespace {

// Iterations per submission: the host reads the stop flags once per batch.
constexpr uint32_t kIterationsPerBatch = 4;

}  // namespace

uint32_t CglsGpuResult::max_iterations() const { return *std::max_element(iterations.begin(), iterations.end()); }

double CglsGpuResult::worst_relative_residual() const {
  return *std::max_element(relative_residual.begin(), relative_residual.end());
}

CglsGpuResult solve_cgls_gpu(VoxelProblem& p, const CglsGpuOptions& options) {
  if (!(options.tolerance > 0.0 && options.tolerance < 1.0))
    throw std::invalid_argument("solve_cgls_gpu: tolerance must be in (0, 1)");
  if (options.max_iterations < 1) throw std::invalid_argument("solve_cgls_gpu: max_iterations must be >= 1");
  const uint32_t max_iterations = options.max_iterations;
  Context& ctx = p.ctx;
  const uint32_t n = p.opt_map.tf_size;

  CglsGpuResult out;
  auto t0 = std::chrono::steady_clock::now();
  if ((options.weights == nullptr) != (options.weighted_system == nullptr))
    throw std::invalid_argument("solve_cgls_gpu: weights and their weighted system go together");
  JacobiSetup js = jacobi_setup(p, options.regularization, options.weighted_system);
  VoxelVectors vectors(ctx, p.ref, p.opt, options.max_chunk_voxels, options.weights != nullptr);
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
  const float ridge = float(js.reg.ridge), smooth = float(js.reg.smooth), tol = float(options.tolerance);

  double setup_gpu_ms = js.gpu_ms;
  {
    CommandBatch batch(ctx);
    const uint32_t a = batch.timestamp();
    prepare.record(batch, p.ref, p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer, vectors, options.weights);
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
    checkpoint("solve");
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
  out.tf = tf_from_floats(xs, &out.clamped_values);
  out.iterations = {st.iterations.x, st.iterations.y, st.iterations.z, st.iterations.w};
  const float s2[4] = {st.s_norm2.x, st.s_norm2.y, st.s_norm2.z, st.s_norm2.w};
  const float s02[4] = {st.s0_norm2.x, st.s0_norm2.y, st.s0_norm2.z, st.s0_norm2.w};
  for (int c = 0; c < 4; ++c)
    out.relative_residual[size_t(c)] = s02[c] > 0.0f ? std::sqrt(double(s2[c]) / double(s02[c])) : 0.0;
  out.voxel_chunks = uint32_t(vectors.chunk_count());
  return out;
}

namespace {

class CglsSolver final : public Solver {
 public:
  std::string_view name() const override { return "cgls"; }
  std::string_view summary() const override {
    return "matrix-free Jacobi-preconditioned CGLS on the GPU, four channels at once";
  }
  SolverConstraints constraints() const override { return {BoxHandling::Clamped, true, true}; }
  std::vector<SolverOption> options() const override {
    std::vector<SolverOption> all = cgls_stop_options();
    for (SolverOption& o : weight_options()) all.push_back(std::move(o));
    return all;
  }

  SolverOutput solve(VoxelProblem& p, const SolverArgs& args) const override {
    SolverOutput out;
    CglsGpuOptions o;
    o.tolerance = args.number("tolerance");
    o.max_iterations = uint32_t(args.integer("max-iterations"));
    o.regularization = args.solve;
    const std::optional<VisibilityWeights> weights = requested_weights(p, args, out);
    std::optional<NormalEquations> system;
    if (weights) {
      system = weighted_system(p, weights->weights, out);
      o.weights = &weights->weights;
      o.weighted_system = &*system;
    }
    const CglsGpuResult r = solve_cgls_gpu(p, o);
    out.tf = r.tf;
    out.phases.insert(out.phases.end(), r.phases.begin(), r.phases.end());
    const double worst = r.worst_relative_residual();
    out.details["iterations"] = r.max_iterations();
    out.details["iterations_per_channel"] = std::vector<uint32_t>(r.iterations.begin(), r.iterations.end());
    out.details["relative_residual"] = worst;  // ||S^T r - R x|| / ||S^T b||, worst channel
    out.details["relative_residual_per_channel"] = std::vector<double>(r.relative_residual.begin(), r.relative_residual.end());
    out.details["tolerance"] = o.tolerance;
    out.details["clamped_values"] = r.clamped_values;
    out.details["voxel_chunks"] = r.voxel_chunks;
    out.details["ridge"] = args.solve.ridge;
    out.details["smooth"] = args.solve.smooth;
    if (worst > o.tolerance) {
      std::ostringstream os;
      os << "CGLS stopped at " << parameter("max-iterations") << " " << o.max_iterations << " with relative residual "
         << worst << " above " << parameter("tolerance") << " " << o.tolerance;
      // Heavy smoothing makes the system too stiff for float32 iterates (--smooth 1e8: residual
      // 3114, an opacity 0.40 where the fit has 0.23).
      if (worst >= 1.0) os << ", no smaller than at the start: the TF may be far from the least-squares fit";
      os << "; " << parameter("solver") << " normal-equations and qp solve the same regularized system exactly";
      out.warnings.push_back(os.str());
    }
    return out;
  }
};

}  // namespace

std::unique_ptr<Solver> make_cgls_solver() { return std::make_unique<CglsSolver>(); }

}  // namespace tfm
