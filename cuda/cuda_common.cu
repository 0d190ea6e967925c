// Device discovery and the CSR helpers shared by the cuSPARSE paths.
#include "cuda_common.cuh"

namespace tfm::cuda {

bool device_available(std::string* why) {
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess || count == 0) {
    if (why) *why = e != cudaSuccess ? cudaGetErrorString(e) : "0 devices";
    return false;
  }
  return true;
}

void require_device(const std::string& who) {
  std::string why;
  if (!device_available(&why)) throw std::runtime_error(who + ": no CUDA device available (cudaGetDeviceCount: " + why + ")");
  check(cudaSetDevice(0), "cudaSetDevice");
}

std::string device_name() {
  cudaDeviceProp prop{};
  if (!device_available() || cudaGetDeviceProperties(&prop, 0) != cudaSuccess) return "no CUDA device";
  return prop.name;
}

DeviceCsr upload_csr(const CsrView& a) {
  DeviceCsr m;
  m.rows = a.rows;
  m.cols = a.cols;
  m.nnz = int64_t(a.col.size());
  m.row_ptr = DeviceArray<int>(a.row_ptr.data(), a.row_ptr.size());
  m.col = DeviceArray<int>(a.col.data(), a.col.size());
  m.val = DeviceArray<double>(a.val.data(), a.val.size());
  return m;
}

DeviceCsr transpose(cusparseHandle_t handle, const DeviceCsr& a) {
  DeviceCsr t;
  t.rows = a.cols;
  t.cols = a.rows;
  t.nnz = a.nnz;
  t.row_ptr = DeviceArray<int>(size_t(a.cols) + 1);
  t.col = DeviceArray<int>(size_t(a.nnz));
  t.val = DeviceArray<double>(size_t(a.nnz));
  if (a.nnz == 0) {
    check(cudaMemset(t.row_ptr.get(), 0, (size_t(a.cols) + 1) * sizeof(int)), "cudaMemset");
    return t;
  }
  size_t bytes = 0;
  check(cusparseCsr2cscEx2_bufferSize(handle, a.rows, a.cols, int(a.nnz), a.val.get(), a.row_ptr.get(), a.col.get(),
                                      t.val.get(), t.row_ptr.get(), t.col.get(), CUDA_R_64F, CUSPARSE_ACTION_NUMERIC,
                                      CUSPARSE_INDEX_BASE_ZERO, CUSPARSE_CSR2CSC_ALG1, &bytes),
        "cusparseCsr2cscEx2_bufferSize");
  DeviceArray<char> buffer(bytes);
  check(cusparseCsr2cscEx2(handle, a.rows, a.cols, int(a.nnz), a.val.get(), a.row_ptr.get(), a.col.get(), t.val.get(),
                           t.row_ptr.get(), t.col.get(), CUDA_R_64F, CUSPARSE_ACTION_NUMERIC, CUSPARSE_INDEX_BASE_ZERO,
                           CUSPARSE_CSR2CSC_ALG1, buffer.get()),
        "cusparseCsr2cscEx2");
  return t;
}

SpMat::SpMat(const DeviceCsr& m) {
  check(cusparseCreateCsr(&d, m.rows, m.cols, m.nnz, m.row_ptr.get(), m.col.get(), m.val.get(), CUSPARSE_INDEX_32I,
                          CUSPARSE_INDEX_32I, CUSPARSE_INDEX_BASE_ZERO, CUDA_R_64F),
        "cusparseCreateCsr");
}

SpMat::SpMat(int64_t rows, int64_t cols) {
  check(cusparseCreateCsr(&d, rows, cols, 0, nullptr, nullptr, nullptr, CUSPARSE_INDEX_32I, CUSPARSE_INDEX_32I,
                          CUSPARSE_INDEX_BASE_ZERO, CUDA_R_64F),
        "cusparseCreateCsr");
}

}  // namespace tfm::cuda
