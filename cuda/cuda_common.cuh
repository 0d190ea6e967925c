// Shared by the .cu files: error checks that throw std::runtime_error, RAII device buffers and
// handles, event timing, and the CSR upload/transposition both cuSPARSE paths need.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include <cuda_runtime.h>
#include <cusparse.h>

#include "cuda_solvers.h"

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
DeviceCsr upload_csr(const CsrView& a);
// A^T as CSR (cusparseCsr2cscEx2: the CSC of A is the CSR of A^T).
DeviceCsr transpose(cusparseHandle_t handle, const DeviceCsr& a);


// Generic-API descriptors (destroyed on scope exit).
struct SpMat {
  cusparseSpMatDescr_t d = nullptr;
  explicit SpMat(const DeviceCsr& m);
  SpMat(int64_t rows, int64_t cols) ;  // an empty CSR result of SpGEMM
  ~SpMat() { if (d) cusparseDestroySpMat(d); }
  SpMat(const SpMat&) = delete;
  SpMat& operator=(const SpMat&) = delete;
};
struct DnVec {
  cusparseDnVecDescr_t d = nullptr;
  DnVec(int64_t size, double* values) { check(cusparseCreateDnVec(&d, size, values, CUDA_R_64F), "cusparseCreateDnVec"); }
  ~DnVec() { if (d) cusparseDestroyDnVec(d); }
  DnVec(const DnVec&) = delete;
  DnVec& operator=(const DnVec&) = delete;
};

// y = M x by cusparseSpMV in double (grows `buffer` as needed).
void spmv(cusparseHandle_t handle, const DeviceCsr& m, const double* x, double* y, DeviceArray<char>& buffer);
// The same with descriptors made once (the CGLS loop).
void spmv(cusparseHandle_t handle, const SpMat& m, const DnVec& x, const DnVec& y, DeviceArray<char>& buffer);

}  // namespace tfm::cuda
