// The matrix-free CUDA assembly of M = S^T S, S^T b, b^T b and the voxel count (the CUDA twin of
// shaders/assemble_normal_equations.comp): one pass over the voxels, 32.32 fixed-point sums with
// 64-bit integer atomics, so the totals are exact and the same on every run.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "tfmatch/cuda/cuda_common.cuh"

namespace tfm::cuda {
namespace {

constexpr int kThreads = 256;
constexpr int kRun = 16;  // contiguous voxels per thread: neighbours mostly share a bin
constexpr size_t kMaxSharedBytes = 48 * 1024;

// Non-negative float below 2^32 to 32.32 fixed point (fx_from_float of tf_common.glsl).
__device__ unsigned long long fx(float c) {
  const float whole = floorf(c);
  const uint32_t lo = uint32_t(__fmul_rn(__fsub_rn(c, whole), 4294967296.0f));
  return (static_cast<unsigned long long>(uint32_t(whole)) << 32) | lo;
}

__device__ void add(unsigned long long* acc, uint32_t slot, unsigned long long v) {
  if (v) atomicAdd(acc + slot, v);
}

// acc: TFM_ASSEMBLE_SLOTS(n) 64-bit sums; in shared memory when `use_shared` (flushed at the end).
__global__ void assemble_kernel(const float* ref, const float* opt, uint64_t count, float ref_lo, float ref_scale,
                                uint32_t ref_n, float opt_lo, float opt_scale, uint32_t n, const float4* ref_tf,
                                unsigned long long* global_acc, bool use_shared) {
  extern __shared__ unsigned long long shared_acc[];
  const uint32_t slots = 6 * n + 8, stb = 2 * n - 1;  // the last 4 (the before loss) stay 0 here
  unsigned long long* acc = use_shared ? shared_acc : global_acc;
  if (use_shared) {
    for (uint32_t k = threadIdx.x; k < slots; k += blockDim.x) shared_acc[k] = 0;
    __syncthreads();
  }
  unsigned long long btb[4] = {0, 0, 0, 0}, voxels = 0;
  uint32_t cur = 0xFFFFFFFFu;
  unsigned long long d0 = 0, d1 = 0, od = 0, s0[4] = {0, 0, 0, 0}, s1[4] = {0, 0, 0, 0};
  auto flush = [&] {
    add(acc, cur, d0);
    add(acc, cur + 1, d1);
    add(acc, n + cur, od);
    for (uint32_t c = 0; c < 4; ++c) {
      add(acc, stb + 4 * cur + c, s0[c]);
      add(acc, stb + 4 * (cur + 1) + c, s1[c]);
    }
  };
  const uint64_t block = uint64_t(blockDim.x) * kRun;
  for (uint64_t base = uint64_t(blockIdx.x) * block; base < count; base += uint64_t(gridDim.x) * block) {
    const uint64_t first = base + uint64_t(threadIdx.x) * kRun;
    const uint64_t last = first + kRun < count ? first + kRun : count;
    for (uint64_t i = first; i < last; ++i) {
      uint32_t jr, jo;
      float wr, wo;
      if (!tf_coordinate(ref[i], ref_lo, ref_scale, ref_n, jr, wr)) continue;
      if (!tf_coordinate(opt[i], opt_lo, opt_scale, n, jo, wo)) continue;
      if (jo != cur) {
        if (cur != 0xFFFFFFFFu) flush();
        cur = jo;
        d0 = d1 = od = 0;
        for (uint32_t c = 0; c < 4; ++c) s0[c] = s1[c] = 0;
      }
      const float4 t0 = ref_tf[jr], t1 = ref_tf[jr + 1];
      const float ur = 1.0f - wr;
      const float b[4] = {fminf(fmaxf(ur * t0.x + wr * t1.x, 0.0f), 1.0f), fminf(fmaxf(ur * t0.y + wr * t1.y, 0.0f), 1.0f),
                          fminf(fmaxf(ur * t0.z + wr * t1.z, 0.0f), 1.0f), fminf(fmaxf(ur * t0.w + wr * t1.w, 0.0f), 1.0f)};
      const float u = 1.0f - wo;
      d0 += fx(u * u);
      d1 += fx(wo * wo);
      od += fx(u * wo);
      for (uint32_t c = 0; c < 4; ++c) {
        s0[c] += fx(u * b[c]);
        s1[c] += fx(wo * b[c]);
        btb[c] += fx(b[c] * b[c]);
      }
      voxels += 1ull << 32;  // 1.0 in 32.32
    }
  }
  if (cur != 0xFFFFFFFFu) flush();
  for (uint32_t c = 0; c < 4; ++c) add(acc, 6 * n - 1 + c, btb[c]);
  add(acc, 6 * n + 3, voxels);
  if (use_shared) {
    __syncthreads();  // every shared add of this block is done before the flush
    for (uint32_t k = threadIdx.x; k < slots; k += blockDim.x) add(global_acc, k, shared_acc[k]);
  }
}

}  // namespace

DirectAssembly assemble_direct(const FieldsOnDevice& f, const FieldMapping& ref_map, const FieldMapping& opt_map,
                               std::span<const float> ref_tf_rgba) {
  if (ref_tf_rgba.size() != size_t(ref_map.tf_size) * 4 || opt_map.tf_size < 2)
    throw std::invalid_argument("assemble_direct: the reference TF does not match its mapping");
  const size_t voxels = f.voxels();
  DirectAssembly out;
  const uint32_t n = opt_map.tf_size;
  const size_t slots = 6 * size_t(n) + 8;  // TFM_ASSEMBLE_SLOTS(n)
  DeviceArray<float> dtf(ref_tf_rgba.data(), ref_tf_rgba.size());
  DeviceArray<unsigned long long> acc(slots);

  const bool use_shared = slots * 8 <= kMaxSharedBytes;
  int sms = 0;
  check(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, 0), "cudaDeviceGetAttribute");
  const uint64_t per_block = uint64_t(kThreads) * kRun;
  const uint64_t wanted = (voxels + per_block - 1) / per_block;
  // A few blocks per SM: enough to fill the device, few enough that the shared flushes are cheap.
  const int blocks = int(std::max<uint64_t>(1, std::min<uint64_t>(wanted, uint64_t(sms) * 8)));
  EventTimer timer;
  timer.start();
  check(cudaMemset(acc.get(), 0, slots * 8), "cudaMemset");
  assemble_kernel<<<blocks, kThreads, use_shared ? slots * 8 : 0>>>(
      f.ref.get(), f.opt.get(), voxels, ref_map.lo, ref_map.scale, ref_map.tf_size, opt_map.lo, opt_map.scale, n,
      reinterpret_cast<const float4*>(dtf.get()), acc.get(), use_shared);
  check(cudaGetLastError(), "assemble_kernel launch");
  out.kernel_ms = timer.stop();
  const std::vector<unsigned long long> fixed = acc.download();
  out.slots.resize(slots);
  for (size_t k = 0; k < slots; ++k) out.slots[k] = std::ldexp(double(fixed[k]), -32);
  return out;
}

}  // namespace tfm::cuda
