// Jacobi-preconditioned CGLS on the explicit A = S (x) I_4 with cuSPARSE SpMM (A p and A^T r as
// S and S^T times n x 4 and voxels x 4 matrices; S and S^T are the DeviceSystem's, built on the
// device), four channels stepping independently like the Vulkan
// `cgls` solver. Every reduction has a fixed shape (grid-stride per thread, then a tree), so runs
// are bit-identical.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "tfmatch/cuda/cuda_common.cuh"

namespace tfm::cuda {
namespace {

constexpr int kThreads = kReduceThreads;
constexpr uint32_t kIterationsPerBatch = 8;  // the host reads the stop flags once per batch

struct State {
  double gamma[4], alpha[4], s_norm2[4], s0_norm2[4];
  uint32_t running[4], iterations[4];
};

// (R v)_k for R = ridge I + smooth D^T D per channel, on interleaved vectors (k = 4j + c).
__device__ double r_times(const double* v, uint32_t k, uint32_t n, double ridge, double smooth) {
  const uint32_t j = k / 4;
  double d = 0.0;
  if (j > 0) d += v[k] - v[k - 4];
  if (j + 1 < n) d += v[k] - v[k + 4];
  return ridge * v[k] + smooth * d;
}

__global__ void init_kernel(uint32_t n, const double* s, const double* inv_diag, double* x, double* p, State* st) {
  __shared__ double sh[kThreads];
  double gz = 0.0, ss = 0.0;
  for (uint32_t k = threadIdx.x; k < 4 * n; k += blockDim.x) {
    const double z = inv_diag[k / 4] * s[k];
    x[k] = 0.0;
    p[k] = z;
    gz += s[k] * z;
    ss += s[k] * s[k];
  }
  double gzt[4], sst[4];
  reduce_channels(gz, sh, gzt);
  reduce_channels(ss, sh, sst);
  if (threadIdx.x < 4) {
    const int c = threadIdx.x;
    st->gamma[c] = gzt[c];
    st->alpha[c] = 0.0;
    st->s_norm2[c] = sst[c];
    st->s0_norm2[c] = sst[c];
    st->iterations[c] = 0;
    st->running[c] = (sst[c] > 0.0 && gzt[c] > 0.0) ? 1u : 0u;  // S^T b = 0: x = 0 solves it
  }
}

// delta = ||A p||^2 + p^T R p per channel; alpha = gamma / delta; x += alpha p.
__global__ void step_kernel(uint32_t n, const double* partials, int partial_blocks, const double* p, double* x,
                            State* st, double ridge, double smooth) {
  __shared__ double sh[kThreads];
  double prp = 0.0;
  for (uint32_t k = threadIdx.x; k < 4 * n; k += blockDim.x) prp += p[k] * r_times(p, k, n, ridge, smooth);
  double delta[4];
  reduce_channels(prp, sh, delta);
  double alpha[4];
  bool ok[4];
  for (int c = 0; c < 4; ++c) {
    for (int b = 0; b < partial_blocks; ++b) delta[c] += partials[4 * b + c];
    ok[c] = delta[c] > 0.0;  // p in the null space (breakdown): that channel stops
    alpha[c] = (st->running[c] && ok[c]) ? st->gamma[c] / delta[c] : 0.0;
  }
  for (uint32_t k = threadIdx.x; k < 4 * n; k += blockDim.x) x[k] += alpha[k % 4] * p[k];
  __syncthreads();  // every thread has read running before it changes
  if (threadIdx.x < 4) {
    st->alpha[threadIdx.x] = alpha[threadIdx.x];
    if (!ok[threadIdx.x]) st->running[threadIdx.x] = 0u;
  }
}

__global__ void residual_kernel(double* r, const double* q, uint64_t len, const State* st) {
  for (uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < len; i += uint64_t(gridDim.x) * blockDim.x)
    r[i] -= st->alpha[i % 4] * q[i];
}

// s = A^T r - R x, z = D^-1 s, beta = (s.z) / gamma, p = z + beta p; the stop test.
__global__ void direction_kernel(uint32_t n, const double* s, const double* inv_diag, const double* x, double* p,
                                 State* st, double ridge, double smooth, double tol2) {
  __shared__ double sh[kThreads];
  double gz = 0.0, ss = 0.0;
  for (uint32_t k = threadIdx.x; k < 4 * n; k += blockDim.x) {
    const double sk = s[k] - r_times(x, k, n, ridge, smooth);
    gz += sk * inv_diag[k / 4] * sk;
    ss += sk * sk;
  }
  double gzt[4], sst[4];
  reduce_channels(gz, sh, gzt);
  reduce_channels(ss, sh, sst);
  bool on[4];
  double beta[4];
  for (int c = 0; c < 4; ++c) {
    on[c] = st->running[c] != 0u;
    beta[c] = on[c] ? gzt[c] / st->gamma[c] : 0.0;
  }
  for (uint32_t k = threadIdx.x; k < 4 * n; k += blockDim.x) {
    if (!on[k % 4]) continue;
    const double sk = s[k] - r_times(x, k, n, ridge, smooth);
    p[k] = inv_diag[k / 4] * sk + beta[k % 4] * p[k];
  }
  __syncthreads();  // every thread has read the state before it changes
  if (threadIdx.x < 4) {
    const int c = threadIdx.x;
    if (on[c]) {
      st->gamma[c] = gzt[c];
      st->s_norm2[c] = sst[c];
      st->iterations[c] += 1;
      if (sst[c] <= tol2 * st->s0_norm2[c] || !(gzt[c] > 0.0)) st->running[c] = 0u;
    }
  }
}

}  // namespace

CglsOutcome cgls(const SystemOnDevice& sys, const CglsParams& prm) {
  const uint32_t n = prm.n;
  if (n != sys.n || prm.inv_diag.size() != n || n < 2 || sys.voxels() == 0)
    throw std::invalid_argument("cuda::cgls: sizes of the system and the Jacobi diagonal do not match, or no voxels");
  CglsOutcome out;
  SparseHandle handle;
  auto t0 = std::chrono::steady_clock::now();
  const uint64_t m = 4 * sys.voxels();  // rows of A: q and r are voxels x 4, row-major
  DeviceArray<double> r(m), q(m), s(4 * size_t(n)), x(4 * size_t(n)), p(4 * size_t(n));
  if (m) check(cudaMemcpy(r.get(), sys.b.get(), m * sizeof(double), cudaMemcpyDeviceToDevice), "r = b");
  DeviceArray<double> inv_diag(prm.inv_diag.data(), n), partials(4 * size_t(kPartialBlocks));
  DeviceArray<State> state(1);
  DeviceArray<char> buffer;
  // A v for an interleaved v is S V for the n x 4 matrix V: the products run on S and S^T.
  const SpMat mat_s(sys.s), mat_st(sys.st);
  const int64_t voxels = int64_t(sys.voxels());
  const DnMat mat_p(n, 4, p.get()), mat_q(voxels, 4, q.get()), mat_r(voxels, 4, r.get()), mat_sv(n, 4, s.get());
  check(cudaDeviceSynchronize(), "CGLS set-up");
  out.setup_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();

  EventTimer timer;
  timer.start();
  const double tol2 = prm.tolerance * prm.tolerance;
  spmm(handle, mat_st, mat_r, mat_sv, buffer);  // s0 = A^T b
  init_kernel<<<1, kThreads>>>(n, s.get(), inv_diag.get(), x.get(), p.get(), state.get());
  check(cudaGetLastError(), "init_kernel");
  State st{};
  check(cudaMemcpy(&st, state.get(), sizeof(st), cudaMemcpyDeviceToHost), "read CGLS state");
  auto running = [&st] { return st.running[0] | st.running[1] | st.running[2] | st.running[3]; };
  uint32_t recorded = 0;
  while (running() && recorded < prm.max_iterations) {
    const uint32_t count = std::min(kIterationsPerBatch, prm.max_iterations - recorded);
    for (uint32_t k = 0; k < count; ++k) {
      spmm(handle, mat_s, mat_p, mat_q, buffer);  // q = A p
      launch_squared_norm_partials(q.get(), m, partials.get());
      step_kernel<<<1, kThreads>>>(n, partials.get(), kPartialBlocks, p.get(), x.get(), state.get(), prm.ridge,
                                   prm.smooth);
      residual_kernel<<<grid_for(m), kThreads>>>(r.get(), q.get(), m, state.get());
      spmm(handle, mat_st, mat_r, mat_sv, buffer);  // s = A^T r
      direction_kernel<<<1, kThreads>>>(n, s.get(), inv_diag.get(), x.get(), p.get(), state.get(), prm.ridge,
                                        prm.smooth, tol2);
    }
    check(cudaGetLastError(), "CGLS kernels");
    recorded += count;
    check(cudaMemcpy(&st, state.get(), sizeof(st), cudaMemcpyDeviceToHost), "read CGLS state");
  }
  out.iterate_ms = timer.stop();
  out.x = x.download();
  for (int c = 0; c < 4; ++c) {
    out.iterations[c] = st.iterations[c];
    out.relative_residual[c] = st.s0_norm2[c] > 0.0 ? std::sqrt(st.s_norm2[c] / st.s0_norm2[c]) : 0.0;
  }
  return out;
}

}  // namespace tfm::cuda
