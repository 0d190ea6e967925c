// The `cgls` solver: matrix-free, preconditioned CGLS on the GPU, four channels at once.
// Per iteration: ||S p||^2 (sparse_gather), alpha and x (cgls_vectors), r -= alpha S p with
// s = S^T r (sparse_scatter), beta and p (cgls_vectors). Iterations are recorded in batches; the
// stop test runs on the GPU per channel, so a stopped channel's later iterations change nothing.
#include "tfmatch/solvers/solver_cgls.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "tfmatch/engine/commands.h"
#include "tfmatch/kernels/sparse_ops.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/parameter_names.h"
#include "tfmatch/solvers/solver_support.h"
#include "tfmatch/solvers/tridiagonal.h"

namespace tfm {
namespace {

// Iterations per submission: the host reads the stop flags once per batch.
constexpr uint32_t kIterationsPerBatch = 4;

}  // namespace

uint32_t CglsGpuResult::max_iterations() const { return *std::max_element(iterations.begin(), iterations.end()); }

double CglsGpuResult::worst_relative_residual() const {
  return *std::max_element(relative_residual.begin(), relative_residual.end());
}

bool CglsGpuResult::any_capped() const { return std::find(capped.begin(), capped.end(), true) != capped.end(); }

CglsFactors cgls_preconditioner(const NormalEquations& eq, const Regularization& reg) {
  if (eq.voxels == 0 || eq.n < 2)
    throw std::invalid_argument("cgls_preconditioner: a system without voxels or with fewer than 2 entries");
  CglsFactors f;
  const Tridiagonal h = regularized_matrix(eq, reg);
  f.inv_pivot.resize(eq.n);
  if (!(reg.smooth > 0.0)) {
    for (uint32_t j = 0; j < eq.n; ++j) f.inv_pivot[j] = h.diag[j] > 0.0 ? float(1.0 / h.diag[j]) : 0.0f;
    return f;
  }
  // diag(M) + R: R's off-diagonal alone (-smooth), so the data's coupling is left to CGLS. Positive
  // definite: D^T D is, except on constants, which any voxel's diag(M) > 0 covers.
  const Tridiagonal p{h.diag, std::vector<double>(eq.n - 1, -reg.smooth)};
  const TridiagonalLdlt ldlt = factor_positive_definite(p);
  for (uint32_t j = 0; j < eq.n; ++j) f.inv_pivot[j] = float(1.0 / ldlt.pivot[j]);
  f.lower.assign(ldlt.lower.begin(), ldlt.lower.end());
  return f;
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
  const JacobiSetup js = jacobi_setup(p, options.regularization, options.weighted_system);
  VoxelVectors vectors(ctx, p.ref, p.opt, options.max_chunk_voxels, options.weights != nullptr);
  const SparsePrepareKernel prepare(ctx);
  DeviceCgls cgls(ctx, n, cgls_preconditioner(js.eq, js.reg),
                  {float(js.reg.ridge), float(js.reg.smooth), float(options.tolerance)});

  double setup_gpu_ms = js.gpu_ms;
  {
    CommandBatch batch(ctx);
    const uint32_t a = batch.timestamp();
    prepare.record(batch, p.ref, p.opt, p.ref_map, p.opt_map, p.ref_tf_buffer, vectors, options.weights);
    cgls.record_start(batch, vectors);
    const uint32_t b = batch.timestamp();
    batch.submit_and_wait();
    if (setup_gpu_ms >= 0 && batch.elapsed_ms(a, b) >= 0) setup_gpu_ms += batch.elapsed_ms(a, b);
  }
  out.phases.push_back({"setup", ms_since(t0), setup_gpu_ms});

  t0 = std::chrono::steady_clock::now();
  double iterate_gpu_ms = 0.0;
  gpu::CglsState st = cgls.read_state(ctx);
  uint32_t recorded = 0;
  auto running = [&st] { return st.running.x | st.running.y | st.running.z | st.running.w; };
  while (running() && recorded < max_iterations) {
    checkpoint("solve");
    const uint32_t count = std::min(kIterationsPerBatch, max_iterations - recorded);
    CommandBatch batch(ctx);
    const uint32_t a = batch.timestamp();
    for (uint32_t k = 0; k < count; ++k) cgls.record_iteration(batch, vectors);
    const uint32_t b = batch.timestamp();
    batch.submit_and_wait();
    iterate_gpu_ms = batch.elapsed_ms(a, b) >= 0 ? iterate_gpu_ms + batch.elapsed_ms(a, b) : -1.0;
    recorded += count;
    st = cgls.read_state(ctx);
  }
  out.phases.push_back({"iterate", ms_since(t0), ctx.timestamps_supported() ? iterate_gpu_ms : -1.0});

  const std::vector<float> xs = cgls.read_x(ctx);
  out.tf = tf_from_floats(xs, &out.clamped_values);
  out.iterations = {st.iterations.x, st.iterations.y, st.iterations.z, st.iterations.w};
  const float s2[4] = {st.s_norm2.x, st.s_norm2.y, st.s_norm2.z, st.s_norm2.w};
  const float s02[4] = {st.s0_norm2.x, st.s0_norm2.y, st.s0_norm2.z, st.s0_norm2.w};
  const double amplification = std::ldexp(1.0, -24) * (js.reg.ridge + 4.0 * js.reg.smooth);
  const uint32_t running_at_end[4] = {st.running.x, st.running.y, st.running.z, st.running.w};
  for (size_t c = 0; c < 4; ++c) {
    out.capped[c] = running_at_end[c] != 0;
    if (!(s02[c] > 0.0f)) continue;
    double xx = 0.0;
    for (uint32_t j = 0; j < n; ++j) xx += double(xs[4 * j + c]) * double(xs[4 * j + c]);
    out.relative_residual[c] = std::sqrt(double(s2[c]) / double(s02[c]));
    out.residual_floor[c] = amplification * std::sqrt(xx / double(s02[c]));
  }
  out.voxel_chunks = uint32_t(vectors.chunk_count());
  return out;
}

namespace {

class CglsSolver final : public Solver {
 public:
  std::string_view name() const override { return "cgls"; }
  std::string_view summary() const override {
    return "matrix-free preconditioned CGLS on the GPU (Jacobi; with --smooth, the smoothing inverted exactly), four "
           "channels at once";
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
    out.details["residual_floor"] = *std::max_element(r.residual_floor.begin(), r.residual_floor.end());
    out.details["tolerance"] = o.tolerance;
    out.details["clamped_values"] = r.clamped_values;
    out.details["voxel_chunks"] = r.voxel_chunks;
    out.details["ridge"] = args.solve.ridge;
    out.details["smooth"] = args.solve.smooth;
    // A channel that stopped at its float32 floor has done what float32 iterates can (the demo's TF
    // within 1e-6 of qp's at every --smooth from 1 to 1e8, 2026-12-06); only the cap is worth a word.
    if (r.any_capped()) {
      std::ostringstream os;
      os << "CGLS stopped at " << parameter("max-iterations") << " " << o.max_iterations << " with relative residual "
         << worst << " above " << parameter("tolerance") << " " << o.tolerance;
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
