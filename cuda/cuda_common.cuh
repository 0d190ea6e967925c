// Shared by the .cu files: error checks that throw std::runtime_error, RAII device buffers and
// handles, event timing, and the CSR upload/transposition both cuSPARSE paths need.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include <cuda_runtime.h>
#include <cusparse.h>

#include "tfmatch/cuda/cuda_solvers.h"

namespace tfm::cuda {

inline void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw std::runtime_error(std::string("CUDA: ") + what + ": " + cudaGetErrorString(e));
}
inline void check(cusparseStatus_t s, const char* what) {
  if (s != CUSPARSE_STATUS_SUCCESS)
    throw std::runtime_error(std::string("cuSPARSE: ") + what + ": " + cusparseGetErrorString(s));
}

// Device memory for `count` elements of T (freed on destruction).
template <class T>
class DeviceArray {
 public:
  DeviceArray() = default;
  explicit DeviceArray(size_t count) : count_(count) {
    if (count) check(cudaMalloc(&ptr_, count * sizeof(T)), "cudaMalloc");
  }
  DeviceArray(const T* host, size_t count) : DeviceArray(count) { upload(host, count); }
  ~DeviceArray() {
    if (ptr_) cudaFree(ptr_);
  }
  DeviceArray(const DeviceArray&) = delete;
  DeviceArray& operator=(const DeviceArray&) = delete;
  DeviceArray(DeviceArray&& o) noexcept : ptr_(o.ptr_), count_(o.count_) { o.ptr_ = nullptr, o.count_ = 0; }
  DeviceArray& operator=(DeviceArray&& o) noexcept {
    std::swap(ptr_, o.ptr_);
    std::swap(count_, o.count_);
    return *this;
  }
  void upload(const T* host, size_t count) {
    if (count) check(cudaMemcpy(ptr_, host, count * sizeof(T), cudaMemcpyHostToDevice), "upload");
  }
  std::vector<T> download() const {
    std::vector<T> out(count_);
    if (count_) check(cudaMemcpy(out.data(), ptr_, count_ * sizeof(T), cudaMemcpyDeviceToHost), "download");
    return out;
  }
  T* get() const { return ptr_; }
  size_t size() const { return count_; }

 private:
  T* ptr_ = nullptr;
  size_t count_ = 0;
};

class SparseHandle {
 public:
  SparseHandle() { check(cusparseCreate(&h_), "cusparseCreate"); }
  ~SparseHandle() { cusparseDestroy(h_); }
  SparseHandle(const SparseHandle&) = delete;
  SparseHandle& operator=(const SparseHandle&) = delete;
  operator cusparseHandle_t() const { return h_; }

 private:
  cusparseHandle_t h_ = nullptr;
};

// Milliseconds between two recorded points of the default stream.
class EventTimer {
 public:
  EventTimer() {
    check(cudaEventCreate(&a_), "cudaEventCreate");
    check(cudaEventCreate(&b_), "cudaEventCreate");
  }
  ~EventTimer() {
    cudaEventDestroy(a_);
    cudaEventDestroy(b_);
  }
  EventTimer(const EventTimer&) = delete;
  EventTimer& operator=(const EventTimer&) = delete;
  void start() { check(cudaEventRecord(a_), "cudaEventRecord"); }
  double stop() {
    check(cudaEventRecord(b_), "cudaEventRecord");
    check(cudaEventSynchronize(b_), "cudaEventSynchronize");
    float ms = 0.0f;
    check(cudaEventElapsedTime(&ms, a_, b_), "cudaEventElapsedTime");
    return ms;
  }

 private:
  cudaEvent_t a_ = nullptr, b_ = nullptr;
};

// A CSR matrix on the device.
struct DeviceCsr {
  int rows = 0, cols = 0;
  int64_t nnz = 0;
  DeviceArray<int> row_ptr, col;
  DeviceArray<double> val;
};
// A^T as CSR (cusparseCsr2cscEx2: the CSC of A is the CSR of A^T).
DeviceCsr transpose(cusparseHandle_t handle, const DeviceCsr& a);

// What DeviceFields and DeviceSystem (cuda_solvers.h) are in this plugin.
class FieldsOnDevice final : public DeviceFields {
 public:
  FieldsOnDevice(std::span<const float> ref_values, std::span<const float> opt_values);  // explicit_system.cu
  DeviceArray<float> ref, opt;
};
class SystemOnDevice final : public DeviceSystem {
 public:
  SystemOnDevice(const FieldsOnDevice& fields, const FieldMapping& ref_map, const FieldMapping& opt_map,
                 std::span<const float> ref_tf_rgba);  // explicit_system.cu
  std::vector<double> column_norms() const override;
  Host download() const override;
  DeviceCsr s, st;        // S (a row per voxel with data, 2 non-zeros a row, n columns) and S^T
  DeviceArray<double> b;  // voxels x 4 row-major: RGBA per voxel with data
  uint32_t n = 0;         // TF entries
};

// The Backend's calls (cuda_solvers.h), one .cu file each: cuda_common.cu, normal_equations_cusparse.cu,
// normal_equations_direct.cu, cgls_cusparse.cu.
bool device_available(std::string* why = nullptr);
void require_device(const std::string& who);
std::string device_name();
CusparseAssembly assemble_cusparse(const SystemOnDevice& system);
DirectAssembly assemble_direct(const FieldsOnDevice& fields, const FieldMapping& ref_map, const FieldMapping& opt_map,
                               std::span<const float> ref_tf_rgba);
CglsOutcome cgls(const SystemOnDevice& system, const CglsParams& params);

// "No data" (DESIGN.md): NaN and ±Inf, as no_data() of shaders/tf_common.glsl and
// host/model/field_mapping.h: an exponent of all ones, tested on the bits.
__device__ inline bool no_data(float v) { return (__float_as_uint(v) & 0x7f800000u) == 0x7f800000u; }

// tf_coordinate() of host/model/field_mapping.h with explicitly rounded float operations (the _rn
// intrinsics are never fused into FMAs), so j and w are bit-identical to the host's.
__device__ inline bool tf_coordinate(float v, float lo, float scale, uint32_t n, uint32_t& j, float& w) {
  if (no_data(v)) return false;
  float x = __fmul_rn(__fsub_rn(v, lo), scale);
  const float top = float(n - 1);
  x = x < 0.0f ? 0.0f : (x > top ? top : x);
  const float jf = fminf(floorf(x), float(n - 2));
  j = uint32_t(jf);
  w = __fsub_rn(x, jf);
  return true;
}

// Threads of the fixed-shape reductions: a power of two and a multiple of 4, so thread t keeps
// channel t % 4 of interleaved RGBA vectors.
constexpr int kReduceThreads = 256;

// Sums v over the block per channel (thread t holds channel t % 4); every thread gets the four
// totals in `out`. `sh` has blockDim.x entries. The tree has a fixed shape: the same bits every run.
__device__ inline void reduce_channels(double v, double* sh, double out[4]) {
  __syncthreads();  // a previous reduction's readers are done with sh
  sh[threadIdx.x] = v;
  __syncthreads();
  for (unsigned half = blockDim.x / 2; half >= 4; half /= 2) {
    if (threadIdx.x < half) sh[threadIdx.x] += sh[threadIdx.x + half];
    __syncthreads();
  }
  for (int c = 0; c < 4; ++c) out[c] = sh[c];
}

// Blocks of kReduceThreads for a grid-stride loop over `len` elements: enough to cover them, at
// most 4096.
inline int grid_for(uint64_t len) {
  const uint64_t blocks = (len + kReduceThreads - 1) / kReduceThreads;
  return int(blocks < 1 ? 1 : (blocks > 4096 ? 4096 : blocks));
}

// Blocks of the long (voxel-sized) reductions: partials has 4 * kPartialBlocks entries.
constexpr int kPartialBlocks = 240;
// partials[4 * block + c] = sum of q_i^2 over block `block`'s entries of channel c (i % 4 == c),
// kPartialBlocks blocks, queued on the default stream.
void launch_squared_norm_partials(const double* q, uint64_t len, double* partials);
// The four channel sums of q_i^2: the partials above, added on the host in block order.
std::array<double, 4> squared_norms_per_channel(const double* q, uint64_t len);


// Generic-API descriptors (destroyed on scope exit).
struct SpMat {
  cusparseSpMatDescr_t d = nullptr;
  explicit SpMat(const DeviceCsr& m);
  SpMat(int64_t rows, int64_t cols) ;  // an empty CSR result of SpGEMM
  ~SpMat() { if (d) cusparseDestroySpMat(d); }
  SpMat(const SpMat&) = delete;
  SpMat& operator=(const SpMat&) = delete;
};
// A dense row-major matrix of doubles, ld = cols: an interleaved RGBA vector is a rows x 4 one.
struct DnMat {
  cusparseDnMatDescr_t d = nullptr;
  DnMat(int64_t rows, int64_t cols, double* values) {
    check(cusparseCreateDnMat(&d, rows, cols, cols, values, CUDA_R_64F, CUSPARSE_ORDER_ROW), "cusparseCreateDnMat");
  }
  ~DnMat() { if (d) cusparseDestroyDnMat(d); }
  DnMat(const DnMat&) = delete;
  DnMat& operator=(const DnMat&) = delete;
};

// Y = M X by cusparseSpMM in double, M never transposed (cuSPARSE repeats its bits then; the
// transposes are explicit CSR matrices). Grows `buffer` as needed.
void spmm(cusparseHandle_t handle, const SpMat& m, const DnMat& x, const DnMat& y, DeviceArray<char>& buffer);

}  // namespace tfm::cuda
