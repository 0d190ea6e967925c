// The explicit system A = S (x) I_4 and b built on the device (a counting pass, a scan, a fill),
// so cuda-normal-equations and cuda-cgls no longer build A on the host (9.2 s of 10.6 s at 41.5 M
// voxels on an H200). Every value is computed with the host's rounding (float TF coordinates by
// explicitly rounded intrinsics, b's double products never fused), so S expanded to A, and b, are
// bit for bit build_explicit_system()'s.
#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>

#include <cub/device/device_scan.cuh>

#include "tfmatch/cuda/cuda_common.cuh"

namespace tfm::cuda {
namespace {

constexpr int kThreads = kReduceThreads;  // grid_for() counts blocks of it
// 2 non-zeros of S per voxel in 32-bit CSR indices (cuSPARSE's csr2csc takes int).
constexpr uint64_t kMaxVoxels = uint64_t(INT_MAX) / 2;

// flags[i] = 1 where both fields have data (NaN and ±Inf are "no data", as everywhere).
__global__ void count_kernel(const float* ref, const float* opt, uint64_t count, uint32_t* flags) {
  for (uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < count; i += uint64_t(gridDim.x) * blockDim.x)
    flags[i] = (!no_data(ref[i]) && !no_data(opt[i])) ? 1u : 0u;
}

struct Mappings {
  float ref_lo, ref_scale, opt_lo, opt_scale;
  uint32_t ref_n, n;
};

// Voxel i with data is row pos[i] of S: (1 - w) at column jo and w at jo + 1 (so rows 4 pos[i] + c
// of A have them at 4 jo + c and 4 (jo + 1) + c), and b's row the reference TF's colour there,
// clamped.
__global__ void fill_kernel(const float* ref, const float* opt, const uint32_t* flags, const uint32_t* pos,
                            uint64_t count, Mappings m, const float* tf, int* col, double* val, double* b) {
  for (uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < count;
       i += uint64_t(gridDim.x) * blockDim.x) {
    if (!flags[i]) continue;
    uint32_t jr = 0, jo = 0;
    float wr = 0.0f, wo = 0.0f;
    tf_coordinate(ref[i], m.ref_lo, m.ref_scale, m.ref_n, jr, wr);
    tf_coordinate(opt[i], m.opt_lo, m.opt_scale, m.n, jo, wo);
    const uint64_t row = uint64_t(pos[i]);
    col[2 * row] = int(jo);
    col[2 * row + 1] = int(jo + 1);
    val[2 * row] = 1.0 - double(wo);
    val[2 * row + 1] = double(wo);
    const double ur = 1.0 - double(wr), wrd = double(wr);
    for (uint32_t c = 0; c < 4; ++c) {
      const double v = __dadd_rn(__dmul_rn(ur, double(tf[4 * jr + c])), __dmul_rn(wrd, double(tf[4 * (jr + 1) + c])));
      b[4 * row + c] = v < 0.0 ? 0.0 : (1.0 < v ? 1.0 : v);  // std::clamp's comparisons
    }
  }
}

__global__ void row_pointer_kernel(uint64_t rows, int* row_ptr) {
  for (uint64_t r = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x; r <= rows; r += uint64_t(gridDim.x) * blockDim.x)
    row_ptr[r] = int(2 * r);
}

// Block j: the sum of squares of row j of S^T (column j of S), strided then a fixed tree.
__global__ void column_norm_kernel(const int* at_row_ptr, const double* at_val, double* out) {
  __shared__ double sh[kThreads];
  const int row = int(blockIdx.x);
  double acc = 0.0;
  for (int k = at_row_ptr[row] + int(threadIdx.x); k < at_row_ptr[row + 1]; k += blockDim.x)
    acc += at_val[k] * at_val[k];
  sh[threadIdx.x] = acc;
  __syncthreads();
  for (unsigned half = blockDim.x / 2; half > 0; half /= 2) {
    if (threadIdx.x < half) sh[threadIdx.x] += sh[threadIdx.x + half];
    __syncthreads();
  }
  if (threadIdx.x == 0) out[blockIdx.x] = sh[0];
}

}  // namespace

FieldsOnDevice::FieldsOnDevice(std::span<const float> ref_values, std::span<const float> opt_values) {
  if (ref_values.size() != opt_values.size())
    throw std::invalid_argument("CUDA fields: the two fields have " + std::to_string(ref_values.size()) + " and " +
                                std::to_string(opt_values.size()) + " voxels");
  const auto t0 = std::chrono::steady_clock::now();
  voxels_ = ref_values.size();
  ref = DeviceArray<float>(ref_values.data(), ref_values.size());
  opt = DeviceArray<float>(opt_values.data(), opt_values.size());
  check(cudaDeviceSynchronize(), "upload of the fields");
  upload_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

SystemOnDevice::SystemOnDevice(const FieldsOnDevice& f, const FieldMapping& ref_map, const FieldMapping& opt_map,
                               std::span<const float> ref_tf_rgba) {
  const uint32_t n = opt_map.tf_size;
  if (n < 2 || ref_map.tf_size < 2 || ref_tf_rgba.size() != size_t(ref_map.tf_size) * 4)
    throw std::invalid_argument("CUDA system: the TFs need at least 2 entries and the reference TF 4 floats each");
  const uint64_t count = f.voxels();
  if (count > kMaxVoxels)
    throw std::invalid_argument("CUDA system: " + std::to_string(count) + " voxels exceed the " +
                                std::to_string(kMaxVoxels) +
                                " that S's 32-bit CSR indices hold (2 non-zeros per voxel)");
  SystemOnDevice& s = *this;
  s.n = n;
  EventTimer timer;
  timer.start();

  // Counting pass and scan: pos[i] = voxels with data before voxel i.
  DeviceArray<uint32_t> flags(count), pos(count);
  if (count) {
    count_kernel<<<grid_for(count), kThreads>>>(f.ref.get(), f.opt.get(), count, flags.get());
    check(cudaGetLastError(), "count_kernel");
    size_t scan_bytes = 0;
    check(cub::DeviceScan::ExclusiveSum(nullptr, scan_bytes, flags.get(), pos.get(), int(count)), "scan (size)");
    DeviceArray<char> scan_buffer(scan_bytes);
    check(cub::DeviceScan::ExclusiveSum(scan_buffer.get(), scan_bytes, flags.get(), pos.get(), int(count)), "scan");
    uint32_t last_pos = 0, last_flag = 0;
    check(cudaMemcpy(&last_pos, pos.get() + (count - 1), sizeof(uint32_t), cudaMemcpyDeviceToHost), "scan total");
    check(cudaMemcpy(&last_flag, flags.get() + (count - 1), sizeof(uint32_t), cudaMemcpyDeviceToHost), "scan total");
    voxels_ = uint64_t(last_pos) + last_flag;
  }

  // Fill: S in CSR (rows of 2 in order, so row_ptr is 2 r) and b.
  const uint64_t rows = voxels_;
  s.s.rows = int(rows);
  s.s.cols = int(n);
  s.s.nnz = int64_t(2 * rows);
  s.s.row_ptr = DeviceArray<int>(rows + 1);
  s.s.col = DeviceArray<int>(2 * rows);
  s.s.val = DeviceArray<double>(2 * rows);
  s.b = DeviceArray<double>(4 * rows);
  DeviceArray<float> tf(ref_tf_rgba.data(), ref_tf_rgba.size());
  row_pointer_kernel<<<grid_for(rows + 1), kThreads>>>(rows, s.s.row_ptr.get());
  check(cudaGetLastError(), "row_pointer_kernel");
  if (voxels_) {
    const Mappings m{ref_map.lo, ref_map.scale, opt_map.lo, opt_map.scale, ref_map.tf_size, n};
    fill_kernel<<<grid_for(count), kThreads>>>(f.ref.get(), f.opt.get(), flags.get(), pos.get(), count, m, tf.get(),
                                               s.s.col.get(), s.s.val.get(), s.b.get());
    check(cudaGetLastError(), "fill_kernel");
  }
  SparseHandle handle;
  s.st = transpose(handle, s.s);
  build_ms_ = timer.stop();
  btb_ = squared_norms_per_channel(s.b.get(), 4 * rows);
}

std::vector<double> SystemOnDevice::column_norms() const {
  DeviceArray<double> out(n);
  column_norm_kernel<<<n, kThreads>>>(st.row_ptr.get(), st.val.get(), out.get());
  check(cudaGetLastError(), "column_norm_kernel");
  return out.download();
}

DeviceSystem::Host SystemOnDevice::download() const {
  return {s.row_ptr.download(), s.col.download(), s.val.download(), b.download()};
}

}  // namespace tfm::cuda
